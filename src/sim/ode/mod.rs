//! Integrators and step-size control shared by both deformation models.
//!
//! Every integrator advances a second-order system `x'' = a(t, x, x')` held as flat `f32`
//! slices (a model lays out its state however it likes, e.g. structure-of-arrays blocks
//! `[x…, y…, z…]`). Time and step sizes are `f64` seconds so long runs do not lose time.
//!
//! An integrator only *proposes* a step: it writes the candidate state into caller buffers and
//! says whether its own error control accepts it and which step to try next. The model then
//! applies its constraints and guards and commits or rejects. This keeps constraint handling
//! (LEMAN 4.2.3) and the blow-up guard outside the integrators, which stay testable on known
//! problems (see the tests at the bottom of this file).
//!
//! The four methods (switchable between any two steps):
//! - [`IntegratorKind::Euler`]: explicit (forward) Euler with a fixed step, first order.
//! - [`IntegratorKind::Verlet`]: the adaptive leapfrog Verlet of LEMAN eq. 7-12, second order,
//!   with a fixed-point iteration for velocity-dependent forces and an embedded Euler error
//!   estimate. Deviation: eq. 7f as printed reads `v + (h/2) a`; the leapfrog update (and the
//!   only consistent one: constant acceleration must give `v + h a`) is `v + h a`, used here.
//!   Addition: the iteration starts from the system's estimate of its fixed point when the
//!   system has one ([`SecondOrderSystem::velocity_fixed_point`]) instead of from `v_t`; its
//!   own convergence test (eq. 7g) still decides when to stop.
//! - [`IntegratorKind::Rk2`]: adaptive Runge-Kutta 2(1) (Heun with embedded Euler).
//! - [`IntegratorKind::Rk4`]: classical fourth-order Runge-Kutta with a fixed step.

#![allow(clippy::needless_range_loop)] // index loops over parallel SoA arrays read best as they are

#[cfg(test)]
mod tests;

use serde::{Deserialize, Serialize};

/// A second-order system `x'' = a(t, x, v)` split into a position-dependent and a
/// velocity-dependent part, so the Verlet fixed-point iteration (LEMAN 4.2.1: "only
/// velocity-dependent forces have to be recomputed") re-evaluates only the cheap part.
pub trait SecondOrderSystem {
    /// Number of scalar degrees of freedom (the length of `x`, `v` and `a`).
    fn dofs(&self) -> usize;

    /// Writes `a = M⁻¹ f_position(t, x)` (all forces that do not depend on velocity). A
    /// system may cache what it derives from `(t, x)` here (e.g. the skeleton pose at `t`)
    /// for the next [`add_velocity_accel`](Self::add_velocity_accel) calls.
    fn position_accel(&mut self, t_s: f64, x: &[f32], a: &mut [f32]);

    /// Adds `M⁻¹ f_velocity(t, x, v)` to `a`, where `t` and `x` are those of the last
    /// [`position_accel`](Self::position_accel) call.
    fn add_velocity_accel(&mut self, t_s: f64, x: &[f32], v: &[f32], a: &mut [f32]);

    /// Writes `a = a_pos + M⁻¹ f_velocity(t, x, v)`, where `a_pos` holds the position part of
    /// the last [`position_accel`](Self::position_accel) call (at the same `t` and `x`). The
    /// result must be bit-identical to copying `a_pos` into `a` and calling
    /// [`add_velocity_accel`](Self::add_velocity_accel), which is the default; a system may
    /// override it to fuse the copy into its first pass (the Verlet iteration calls this once
    /// per velocity evaluation).
    fn velocity_accel_from(
        &mut self,
        t_s: f64,
        x: &[f32],
        v: &[f32],
        a_pos: &[f32],
        a: &mut [f32],
    ) {
        a.copy_from_slice(a_pos);
        self.add_velocity_accel(t_s, x, v, a);
    }

    /// A start for the Verlet velocity iteration (LEMAN eq. 7b-g): writes into `v_new` the
    /// system's estimate of the iteration's fixed point `v⁺ = v + h a(t, x, (v + v⁺)/2)`, where
    /// `t` and `x` are those of the last [`position_accel`](Self::position_accel) call and
    /// `a_pos` its result, and returns true; or returns false, leaving `v_new` alone, and the
    /// iteration starts from `v` as in the paper. The iteration's own test (eq. 7g) still
    /// decides when it has converged, so a poor estimate only costs evaluations; a system whose
    /// velocity forces act point by point can solve the fixed point exactly and save most of
    /// them. The default has no estimate.
    fn velocity_fixed_point(
        &mut self,
        t_s: f64,
        x: &[f32],
        v: &[f32],
        a_pos: &[f32],
        h_s: f64,
        v_new: &mut [f32],
    ) -> bool {
        let _ = (t_s, x, v, a_pos, h_s, v_new);
        false
    }

    /// Whether any force depends on velocity. When not, Verlet needs a single evaluation.
    fn has_velocity_forces(&self) -> bool {
        true
    }

    /// Removes from a step's position error the part the system's own constraints absorb.
    ///
    /// `error` holds, per degree of freedom and unscaled, the embedded Euler position minus the
    /// proposed one (`(x + h v) − x_new`, LEMAN eq. 9); `x` is the state at the step's start.
    /// A model that projects points out of obstacles after each step (LEMAN 4.2.3) may drop
    /// the component of a contact point's error that points into the obstacle: the constraint
    /// replaces that part of the motion and controls it with its own tolerance ε_c, so it
    /// should not limit the step. The step control then takes the scaled ∞-norm (eq. 8, 11)
    /// of what is left. Called once per adaptive step proposal; the default leaves the error
    /// as it is.
    fn absorbed_error(&self, x: &[f32], error: &mut [f32]) {
        let _ = (x, error);
    }
}

/// Which integration method to use. Switchable between steps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum IntegratorKind {
    /// Explicit Euler, fixed step [`Tolerances::euler_step_s`].
    Euler,
    /// Adaptive leapfrog Verlet 2(1), LEMAN eq. 7-12.
    Verlet,
    /// Adaptive Runge-Kutta 2(1) (Heun with embedded Euler).
    Rk2,
    /// Classical Runge-Kutta 4, fixed step [`Tolerances::rk4_step_s`].
    Rk4,
}

impl IntegratorKind {
    /// All methods, in the order of the paper's Table 1 then RK4.
    pub const ALL: [IntegratorKind; 4] = [
        IntegratorKind::Euler,
        IntegratorKind::Verlet,
        IntegratorKind::Rk2,
        IntegratorKind::Rk4,
    ];

    /// Lower-case name as used on the command line and in JSON.
    pub fn name(self) -> &'static str {
        match self {
            IntegratorKind::Euler => "euler",
            IntegratorKind::Verlet => "verlet",
            IntegratorKind::Rk2 => "rk2",
            IntegratorKind::Rk4 => "rk4",
        }
    }

    /// Parses a lower-case name (`euler`, `verlet`, `rk2`, `rk4`).
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == name)
    }

    /// Whether the method chooses its own step size.
    pub fn is_adaptive(self) -> bool {
        matches!(self, IntegratorKind::Verlet | IntegratorKind::Rk2)
    }

    /// The character file's `[simulation]` field that sets this method's fixed step
    /// (`euler_step_s`, `rk4_step_s`), or `None` for the adaptive methods, which choose their
    /// own.
    pub fn fixed_step_field(self) -> Option<&'static str> {
        match self {
            IntegratorKind::Euler => Some("euler_step_s"),
            IntegratorKind::Rk4 => Some("rk4_step_s"),
            IntegratorKind::Verlet | IntegratorKind::Rk2 => None,
        }
    }
}

/// Step-size control parameters (LEMAN 4.2.1-4.2.2). Errors are scaled per component by
/// `1 / max(|value|, threshold)` (eq. 8): absolute below the threshold, relative above.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Tolerances {
    /// Step of explicit Euler (fixed step), seconds.
    pub euler_step_s: f64,
    /// Step of classical Runge-Kutta 4 (fixed step), seconds. Its own setting: RK4 stays
    /// stable at steps where explicit Euler slowly diverges.
    pub rk4_step_s: f64,
    /// Smallest step the adaptive methods take, seconds. A step at this size is accepted
    /// whatever its error (and counted as forced).
    pub min_step_s: f64,
    /// Largest step the adaptive methods take, seconds.
    pub max_step_s: f64,
    /// ε^(r): accepted scaled position error per step (eq. 11-12).
    pub position_tolerance: f64,
    /// ε^(v): convergence tolerance of the Verlet velocity iteration (eq. 7g).
    pub velocity_tolerance: f64,
    /// r^(threshold): position magnitude above which the position error is relative, metres.
    pub position_threshold_m: f64,
    /// v^(threshold): velocity magnitude above which the velocity error is relative, m/s.
    pub velocity_threshold_m_per_s: f64,
    /// Maximum Verlet velocity iterations before the step is rejected and halved.
    pub max_velocity_iterations: u32,
    /// Safety factor on the proposed next step (`< 1`).
    pub safety: f64,
    /// Largest factor by which the step may grow from one step to the next.
    pub max_growth: f64,
    /// Smallest factor by which a rejected step shrinks.
    pub max_shrink: f64,
}

/// The most velocity iterations per Verlet step [`Tolerances::check`] allows (the default is 8;
/// the iteration converges linearly, so more than this means it will not).
pub const MAX_VELOCITY_ITERATIONS: u32 = 1000;

impl Tolerances {
    /// The step of a fixed-step method ([`Tolerances::euler_step_s`] or
    /// [`Tolerances::rk4_step_s`]); for the adaptive methods, which have none, Euler's.
    pub fn fixed_step_s(&self, kind: IntegratorKind) -> f64 {
        match kind {
            IntegratorKind::Rk4 => self.rk4_step_s,
            IntegratorKind::Euler | IntegratorKind::Verlet | IntegratorKind::Rk2 => {
                self.euler_step_s
            }
        }
    }

    /// The shortest step the simulator takes or retries with `kind`: [`Tolerances::min_step_s`],
    /// or a fixed-step method's own step where that is shorter, seconds. A fixed step below
    /// `min_step_s` (a skin resampled finer, a file, the panel's slider) is taken as it is, not
    /// lengthened to the floor.
    pub fn step_floor_s(&self, kind: IntegratorKind) -> f64 {
        if kind.is_adaptive() {
            self.min_step_s
        } else {
            self.min_step_s.min(self.fixed_step_s(kind))
        }
    }

    /// Whether `step_s` is the smallest step (within rounding), where an adaptive method accepts
    /// any finite error (counted as forced).
    pub fn at_min_step(&self, step_s: f64) -> bool {
        step_s <= self.min_step_s * (1.0 + 1e-9)
    }

    /// Whether every value is in its range, or the first that is not, named: the steps,
    /// tolerances and thresholds finite and positive (in `f32`, as the simulator uses them) with `max_step_s ≥ min_step_s`, the
    /// safety factor in (0, 1], the largest shrink of a step in (0, 1) and the largest growth
    /// at least 1 (so a rejected step always shrinks and the controller's clamp is well formed),
    /// and the velocity iterations in `1..=MAX_VELOCITY_ITERATIONS` (each is a force
    /// evaluation, and an attempt must end).
    pub fn check(&self) -> Result<(), String> {
        for (name, v) in [
            ("euler_step_s", self.euler_step_s),
            ("rk4_step_s", self.rk4_step_s),
            ("min_step_s", self.min_step_s),
            ("max_step_s", self.max_step_s),
            ("position_tolerance", self.position_tolerance),
            ("velocity_tolerance", self.velocity_tolerance),
            ("position_threshold_m", self.position_threshold_m),
            (
                "velocity_threshold_m_per_s",
                self.velocity_threshold_m_per_s,
            ),
            ("safety", self.safety),
            ("max_growth", self.max_growth),
            ("max_shrink", self.max_shrink),
        ] {
            // The skin is simulated in single precision: the value must survive the cast.
            let single = v as f32;
            if !(single.is_finite() && single > 0.0) {
                return Err(format!(
                    "{name} must be finite and > 0 in single precision, got {v}"
                ));
            }
        }
        if self.max_step_s < self.min_step_s {
            return Err(format!(
                "max_step_s {} is below min_step_s {}",
                self.max_step_s, self.min_step_s
            ));
        }
        if self.safety > 1.0 {
            return Err(format!("safety must be at most 1, got {}", self.safety));
        }
        if self.max_shrink >= 1.0 {
            return Err(format!(
                "max_shrink must be below 1, got {}",
                self.max_shrink
            ));
        }
        if self.max_growth < 1.0 {
            return Err(format!(
                "max_growth must be at least 1, got {}",
                self.max_growth
            ));
        }
        if !(1..=MAX_VELOCITY_ITERATIONS).contains(&self.max_velocity_iterations) {
            return Err(format!(
                "max_velocity_iterations must be in 1..={MAX_VELOCITY_ITERATIONS}, got {}",
                self.max_velocity_iterations
            ));
        }
        Ok(())
    }
}

impl Default for Tolerances {
    fn default() -> Self {
        Self {
            euler_step_s: 0.002,
            rk4_step_s: 0.002,
            min_step_s: 0.000_5,
            max_step_s: 0.016,
            position_tolerance: 1.0e-4,
            velocity_tolerance: 1.0e-3,
            position_threshold_m: 1.0,
            velocity_threshold_m_per_s: 1.0,
            max_velocity_iterations: 8,
            safety: 0.9,
            max_growth: 1.5,
            max_shrink: 0.2,
        }
    }
}

/// What an integrator says about one proposed step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Proposal {
    /// The step that was attempted, seconds.
    pub step_s: f64,
    /// Scaled error divided by the tolerance (`≤ 1` means acceptable); 0 for fixed-step methods.
    pub error_ratio: f64,
    /// Whether the integrator's own error control accepts the step.
    pub accepted: bool,
    /// Whether the step was accepted only because it was already at the minimum step.
    pub forced: bool,
    /// The step to try next (after acceptance) or to retry with (after rejection), seconds.
    pub next_step_s: f64,
    /// Full (position + velocity) force evaluations used.
    pub position_evals: u32,
    /// Velocity-only force evaluations used (Verlet iterations).
    pub velocity_evals: u32,
}

/// An integrator with its scratch buffers (no allocation per step once sized).
#[derive(Debug, Clone)]
pub struct Integrator {
    kind: IntegratorKind,
    /// Step-size parameters; may be changed between steps.
    pub tolerances: Tolerances,
    scratch: [Vec<f32>; 6],
}

impl Integrator {
    /// A new integrator of `kind`.
    pub fn new(kind: IntegratorKind, tolerances: Tolerances) -> Self {
        Self {
            kind,
            tolerances,
            scratch: Default::default(),
        }
    }

    /// The current method.
    pub fn kind(&self) -> IntegratorKind {
        self.kind
    }

    /// Switches method (takes effect at the next step).
    pub fn set_kind(&mut self, kind: IntegratorKind) {
        self.kind = kind;
    }

    /// The step to start with for the current method: its fixed step
    /// ([`Tolerances::fixed_step_s`]), or for the adaptive methods Euler's step clamped into
    /// `[min_step_s, max_step_s]`.
    pub fn initial_step_s(&self) -> f64 {
        let t = &self.tolerances;
        let fixed = t.fixed_step_s(self.kind);
        if self.kind.is_adaptive() {
            fixed.clamp(t.min_step_s, t.max_step_s.max(t.min_step_s))
        } else {
            fixed
        }
    }

    fn ensure(&mut self, n: usize) {
        for s in &mut self.scratch {
            if s.len() != n {
                s.resize(n, 0.0);
            }
        }
    }

    /// Proposes one step of size `step_s` from `(x, v)` at time `t_s`, writing the candidate
    /// state into `x_new`, `v_new`. Nothing is committed: the caller decides.
    ///
    /// All slices must have length `sys.dofs()`; on a mismatch nothing is done and the proposal
    /// says rejected with the same step (a programming error, never a panic).
    #[allow(clippy::too_many_arguments)]
    pub fn propose<S: SecondOrderSystem + ?Sized>(
        &mut self,
        sys: &mut S,
        t_s: f64,
        step_s: f64,
        x: &[f32],
        v: &[f32],
        x_new: &mut [f32],
        v_new: &mut [f32],
    ) -> Proposal {
        let n = sys.dofs();
        if x.len() != n || v.len() != n || x_new.len() != n || v_new.len() != n {
            return Proposal {
                step_s,
                error_ratio: f64::INFINITY,
                accepted: false,
                forced: false,
                next_step_s: step_s,
                position_evals: 0,
                velocity_evals: 0,
            };
        }
        self.ensure(n);
        match self.kind {
            IntegratorKind::Euler => self.euler(sys, t_s, step_s, x, v, x_new, v_new),
            IntegratorKind::Verlet => self.verlet(sys, t_s, step_s, x, v, x_new, v_new),
            IntegratorKind::Rk2 => self.rk2(sys, t_s, step_s, x, v, x_new, v_new),
            IntegratorKind::Rk4 => self.rk4(sys, t_s, step_s, x, v, x_new, v_new),
        }
    }

    fn fixed(&self, step_s: f64, position_evals: u32) -> Proposal {
        Proposal {
            step_s,
            error_ratio: 0.0,
            accepted: true,
            forced: false,
            next_step_s: self.tolerances.fixed_step_s(self.kind),
            position_evals,
            velocity_evals: 0,
        }
    }

    /// Accept/reject and next step from a scaled error of a method of order 2 with an
    /// embedded order-1 estimate (eq. 12: `h₁ = h (Δ/ε)^(-1/2)`).
    fn adapt(
        &self,
        step_s: f64,
        error_ratio: f64,
        position_evals: u32,
        velocity_evals: u32,
    ) -> Proposal {
        let t = &self.tolerances;
        let factor = if error_ratio.is_finite() && error_ratio > 0.0 {
            (t.safety / error_ratio.sqrt()).clamp(t.max_shrink, t.max_growth)
        } else if error_ratio == 0.0 {
            t.max_growth
        } else {
            t.max_shrink
        };
        let at_min = t.at_min_step(step_s);
        let ok = error_ratio.is_finite() && error_ratio <= 1.0;
        let accepted = ok || (at_min && error_ratio.is_finite());
        let next = (step_s * factor).clamp(t.min_step_s, t.max_step_s.max(t.min_step_s));
        Proposal {
            step_s,
            error_ratio,
            accepted,
            forced: accepted && !ok,
            next_step_s: next,
            position_evals,
            velocity_evals,
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn euler<S: SecondOrderSystem + ?Sized>(
        &mut self,
        sys: &mut S,
        t_s: f64,
        h64: f64,
        x: &[f32],
        v: &[f32],
        x_new: &mut [f32],
        v_new: &mut [f32],
    ) -> Proposal {
        let h = h64 as f32;
        let a = &mut self.scratch[0];
        sys.position_accel(t_s, x, a);
        sys.add_velocity_accel(t_s, x, v, a);
        for i in 0..x.len() {
            x_new[i] = x[i] + h * v[i];
            v_new[i] = v[i] + h * a[i];
        }
        self.fixed(h64, 1)
    }

    #[allow(clippy::too_many_arguments)]
    fn verlet<S: SecondOrderSystem + ?Sized>(
        &mut self,
        sys: &mut S,
        t_s: f64,
        h64: f64,
        x: &[f32],
        v: &[f32],
        x_new: &mut [f32],
        v_new: &mut [f32],
    ) -> Proposal {
        let tol = self.tolerances;
        let h = h64 as f32;
        let half = 0.5 * h;
        let [x_half, a_pos, a, v_mid, inv_v_scale, _] = &mut self.scratch;
        let vel = sys.has_velocity_forces();
        let v_thr = tol.velocity_threshold_m_per_s as f32;
        // (7a) r_{t+h/2} = r_t + h/2 v_t. (7b) v_{t+h} = v_t and (7c) of the first iteration,
        // v_{t+h/2} = v_t, are not copied: the first iteration reads v_t in their place.
        verlet_start(x, v, half, x_half);
        let t_half = t_s + 0.5 * h64;
        sys.position_accel(t_half, x_half, a_pos);
        let eps_v = tol.velocity_tolerance as f32;
        let max_iter = tol.max_velocity_iterations.max(1);
        let mut velocity_evals = 0;
        let mut converged = !vel;
        if !vel {
            for ((vn, vi), ai) in v_new.iter_mut().zip(v).zip(a_pos.iter()) {
                *vn = vi + h * ai;
            }
        } else {
            // (7b) v_{t+h} = v_t, unless the system can do better: from its estimate of the
            // fixed point, (7c) v_{t+h/2} = (v_t + v_{t+h})/2 and the eq. 8 velocity scales
            // 1/max(|v_t|, v^thr) are taken here, and the first iteration may already pass
            // the test below.
            let started = sys.velocity_fixed_point(t_half, x_half, v, a_pos, h64, v_new);
            if started {
                verlet_velocity_start(v, v_thr, v_new, v_mid, inv_v_scale);
            }
            for it in 0..max_iter {
                // (7d) a = M⁻¹ f(r_{t+h/2}, v_{t+h/2}); only the velocity part changes.
                let from_v = it == 0 && !started;
                let v_half: &[f32] = if from_v { v } else { v_mid };
                sys.velocity_accel_from(t_half, x_half, v_half, a_pos, a);
                velocity_evals += 1;
                // (7e-7g) v_old = v_{t+h}; v_{t+h} = v_t + h a; until scaled change ≤ ε_v;
                // fused with the next iteration's (7c). A first iteration from v_t also takes
                // the eq. 8 velocity scales 1/max(|v_t|, v^thr).
                let change = if from_v {
                    verlet_velocity_first(v, v_thr, h, a, v_new, v_mid, inv_v_scale)
                } else {
                    verlet_velocity_update(v, inv_v_scale, h, a, v_new, v_mid)
                };
                if !from_v && change <= eps_v {
                    converged = true;
                    break;
                }
                if !change.is_finite() {
                    break;
                }
            }
        }
        // (7h) r_{t+h} = r_{t+h/2} + h/2 v_{t+h}; (9, 11) Δ = ‖(r_t + h v_t − r_{t+h}) r_scale‖∞
        let r_thr = tol.position_threshold_m as f32;
        // The error is kept as a vector so the system can drop what its constraints absorb
        // before the norm is taken (it reuses the velocity scales' buffer).
        let error = inv_v_scale;
        verlet_finish(x, v, x_half, v_new, half, h, x_new, error);
        sys.absorbed_error(x, error);
        let delta = scaled_max_abs(x, error, r_thr);
        let mut ratio = f64::from(delta) / tol.position_tolerance;
        if !delta.is_finite() {
            ratio = f64::INFINITY;
        }
        if !converged {
            // The fixed point did not settle: treat as a failed step and halve.
            let mut p = self.adapt(h64, f64::INFINITY, 1, velocity_evals);
            p.next_step_s = (0.5 * h64).max(tol.min_step_s);
            if tol.at_min_step(h64) && ratio.is_finite() {
                p.accepted = true;
                p.forced = true;
                p.error_ratio = ratio;
            }
            return p;
        }
        self.adapt(h64, ratio, 1, velocity_evals)
    }

    #[allow(clippy::too_many_arguments)]
    fn rk2<S: SecondOrderSystem + ?Sized>(
        &mut self,
        sys: &mut S,
        t_s: f64,
        h64: f64,
        x: &[f32],
        v: &[f32],
        x_new: &mut [f32],
        v_new: &mut [f32],
    ) -> Proposal {
        let tol = self.tolerances;
        let h = h64 as f32;
        let [a1, a2, x1, v1, error, _] = &mut self.scratch;
        sys.position_accel(t_s, x, a1);
        sys.add_velocity_accel(t_s, x, v, a1);
        for i in 0..x.len() {
            x1[i] = x[i] + h * v[i];
            v1[i] = v[i] + h * a1[i];
        }
        sys.position_accel(t_s + h64, x1, a2);
        sys.add_velocity_accel(t_s + h64, x1, v1, a2);
        let r_thr = tol.position_threshold_m as f32;
        let v_thr = tol.velocity_threshold_m_per_s as f32;
        // The position error is kept as a vector (Euler minus Heun) for the system to trim
        // what its constraints absorb before its norm is taken; the velocity error is not.
        let mut err = 0.0f32;
        for i in 0..x.len() {
            // Heun: x₂ = x + h/2 (v + v₁), v₂ = v + h/2 (a₁ + a₂); Euler: (x₁, v₁).
            let xn = x[i] + 0.5 * h * (v[i] + v1[i]);
            let vn = v[i] + 0.5 * h * (a1[i] + a2[i]);
            // Velocity error is scaled to a position-like quantity by multiplying with h so one
            // tolerance governs both (both are O(h²)).
            let ev = h * (vn - v1[i]).abs() / v[i].abs().max(v_thr);
            error[i] = x1[i] - xn;
            err = err.max(ev);
            x_new[i] = xn;
            v_new[i] = vn;
        }
        sys.absorbed_error(x, error);
        err = err.max(scaled_max_abs(x, error, r_thr));
        let ratio = if err.is_finite() {
            f64::from(err) / tol.position_tolerance
        } else {
            f64::INFINITY
        };
        self.adapt(h64, ratio, 2, 0)
    }

    #[allow(clippy::too_many_arguments)]
    fn rk4<S: SecondOrderSystem + ?Sized>(
        &mut self,
        sys: &mut S,
        t_s: f64,
        h64: f64,
        x: &[f32],
        v: &[f32],
        x_new: &mut [f32],
        v_new: &mut [f32],
    ) -> Proposal {
        let h = h64 as f32;
        let half = 0.5 * h;
        let [a1, a2, a3, a4, xs, vs] = &mut self.scratch;
        // k1 = (v, a1)
        sys.position_accel(t_s, x, a1);
        sys.add_velocity_accel(t_s, x, v, a1);
        // k2 at (x + h/2 v, v + h/2 a1)
        for i in 0..x.len() {
            xs[i] = x[i] + half * v[i];
            vs[i] = v[i] + half * a1[i];
        }
        sys.position_accel(t_s + 0.5 * h64, xs, a2);
        sys.add_velocity_accel(t_s + 0.5 * h64, xs, vs, a2);
        // x_new / v_new hold the running sums: Σ b_i k_i.
        for i in 0..x.len() {
            x_new[i] = v[i] + 2.0 * vs[i];
            v_new[i] = a1[i] + 2.0 * a2[i];
        }
        // k3 at (x + h/2 v2, v + h/2 a2), v2 = vs
        for i in 0..x.len() {
            let v2 = vs[i];
            xs[i] = x[i] + half * v2;
            vs[i] = v[i] + half * a2[i];
        }
        sys.position_accel(t_s + 0.5 * h64, xs, a3);
        sys.add_velocity_accel(t_s + 0.5 * h64, xs, vs, a3);
        for i in 0..x.len() {
            x_new[i] += 2.0 * vs[i];
            v_new[i] += 2.0 * a3[i];
        }
        // k4 at (x + h v3, v + h a3)
        for i in 0..x.len() {
            let v3 = vs[i];
            xs[i] = x[i] + h * v3;
            vs[i] = v[i] + h * a3[i];
        }
        sys.position_accel(t_s + h64, xs, a4);
        sys.add_velocity_accel(t_s + h64, xs, vs, a4);
        let sixth = h / 6.0;
        for i in 0..x.len() {
            let dx = x_new[i] + vs[i];
            let dv = v_new[i] + a4[i];
            x_new[i] = x[i] + sixth * dx;
            v_new[i] = v[i] + sixth * dv;
        }
        self.fixed(h64, 4)
    }
}

/// Statistics of [`integrate`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct IntegrateStats {
    /// Accepted steps.
    pub accepted: u64,
    /// Rejected attempts.
    pub rejected: u64,
    /// Smallest accepted step, seconds.
    pub min_step_s: f64,
    /// Largest accepted step, seconds.
    pub max_step_s: f64,
}

/// Integrates an unconstrained system from `t0_s` to `t1_s` in place, with the method's own
/// step control (the last step is shortened to land on `t1_s`). Meant for tests and simple
/// systems; the deformation models have their own drivers that add constraints and guards.
pub fn integrate<S: SecondOrderSystem + ?Sized>(
    integrator: &mut Integrator,
    sys: &mut S,
    t0_s: f64,
    t1_s: f64,
    x: &mut [f32],
    v: &mut [f32],
) -> IntegrateStats {
    let n = x.len();
    let mut xn = vec![0.0f32; n];
    let mut vn = vec![0.0f32; n];
    let mut t = t0_s;
    let mut h = integrator.initial_step_s();
    let mut stats = IntegrateStats {
        min_step_s: f64::INFINITY,
        ..Default::default()
    };
    let mut guard = 0u64;
    while t < t1_s - 1e-12 && guard < 100_000_000 {
        guard += 1;
        let step = h.min(t1_s - t);
        let p = integrator.propose(sys, t, step, x, v, &mut xn, &mut vn);
        if p.accepted {
            x.copy_from_slice(&xn);
            v.copy_from_slice(&vn);
            t += step;
            stats.accepted += 1;
            stats.min_step_s = stats.min_step_s.min(step);
            stats.max_step_s = stats.max_step_s.max(step);
            // A step shortened to land on t1 does not shrink the controller's step.
            h = if step < h {
                h.max(p.next_step_s)
            } else {
                p.next_step_s
            };
        } else {
            stats.rejected += 1;
            h = p.next_step_s;
        }
    }
    stats
}

// The Verlet passes over the state: each a single fused, vectorizable loop (see
// `crate::sim::simd`), compiled for the baseline CPU, AVX2 and AVX-512.

crate::sim::simd::multiversion! {
    /// Verlet's first pass: `x_half = x + h/2 v`.
    fn verlet_start(x: &[f32], v: &[f32], half: f32, x_half: &mut [f32]) {
        for ((x, v), x_half) in x.iter().zip(v).zip(x_half.iter_mut()) {
            *x_half = x + half * v;
        }
    }
}

crate::sim::simd::multiversion! {
    /// The first Verlet velocity iteration after the force evaluation (eq. 7e-7g with
    /// `v_{t+h} = v` before it, then 7c of the next iteration): `v⁺ = v + h a`, the eq. 8
    /// velocity scale `inv_v_scale = 1 / max(|v|, v_thr)`, returns `max |v⁺ − v| · inv_v_scale`
    /// (NaN or ∞ when any is), then `v_new = v⁺` and `v_mid = (v⁺ + v)/2`.
    fn verlet_velocity_first(
        v: &[f32],
        v_thr: f32,
        h: f32,
        a: &[f32],
        v_new: &mut [f32],
        v_mid: &mut [f32],
        inv_v_scale: &mut [f32],
    ) -> f32 {
        use crate::sim::simd::{LANES, MaxLanes};
        #[inline(always)]
        fn one(v: f32, a: f32, v_thr: f32, h: f32, v_new: &mut f32, v_mid: &mut f32, s: &mut f32) -> f32 {
            let scale = 1.0 / v.abs().max(v_thr);
            let nv = v + h * a;
            let d = (nv - v).abs() * scale;
            *s = scale;
            *v_new = nv;
            *v_mid = 0.5 * (nv + v);
            d
        }
        let mut acc = MaxLanes::new();
        let (vc, vr) = v.as_chunks::<LANES>();
        let (ac, ar) = a.as_chunks::<LANES>();
        let (nc, nr) = v_new.as_chunks_mut::<LANES>();
        let (mc, mr) = v_mid.as_chunks_mut::<LANES>();
        let (sc, sr) = inv_v_scale.as_chunks_mut::<LANES>();
        for ((((v, a), vn), vm), s) in vc.iter().zip(ac).zip(nc).zip(mc).zip(sc) {
            for l in 0..LANES {
                acc.push(l, one(v[l], a[l], v_thr, h, &mut vn[l], &mut vm[l], &mut s[l]));
            }
        }
        for (l, ((((v, a), vn), vm), s)) in vr.iter().zip(ar).zip(nr).zip(mr).zip(sr).enumerate() {
            acc.push(l, one(*v, *a, v_thr, h, vn, vm, s));
        }
        acc.finish()
    }
}

crate::sim::simd::multiversion! {
    /// The Verlet velocity iteration's start from a system's estimate `v_new` of its fixed
    /// point ([`SecondOrderSystem::velocity_fixed_point`]): eq. 7c `v_mid = (v_new + v)/2`
    /// and the eq. 8 velocity scale `inv_v_scale = 1 / max(|v|, v_thr)`.
    fn verlet_velocity_start(
        v: &[f32],
        v_thr: f32,
        v_new: &[f32],
        v_mid: &mut [f32],
        inv_v_scale: &mut [f32],
    ) {
        let n = v.len().min(v_new.len()).min(v_mid.len()).min(inv_v_scale.len());
        let (v, v_new) = (&v[..n], &v_new[..n]);
        let (v_mid, inv_v_scale) = (&mut v_mid[..n], &mut inv_v_scale[..n]);
        for i in 0..n {
            inv_v_scale[i] = 1.0 / v[i].abs().max(v_thr);
            v_mid[i] = 0.5 * (v_new[i] + v[i]);
        }
    }
}

crate::sim::simd::multiversion! {
    /// One later Verlet velocity iteration after the force evaluation (eq. 7e-7g, then 7c of
    /// the next iteration): `v⁺ = v + h a`, returns `max |v⁺ − v_new| · inv_v_scale` (NaN or ∞
    /// when any is), then `v_new = v⁺` and `v_mid = (v⁺ + v)/2`.
    fn verlet_velocity_update(
        v: &[f32],
        inv_v_scale: &[f32],
        h: f32,
        a: &[f32],
        v_new: &mut [f32],
        v_mid: &mut [f32],
    ) -> f32 {
        use crate::sim::simd::{LANES, MaxLanes};
        #[inline(always)]
        fn one(v: f32, scale: f32, h: f32, a: f32, v_new: &mut f32, v_mid: &mut f32) -> f32 {
            let nv = v + h * a;
            let d = (nv - *v_new).abs() * scale;
            *v_new = nv;
            *v_mid = 0.5 * (nv + v);
            d
        }
        let mut acc = MaxLanes::new();
        let (vc, vr) = v.as_chunks::<LANES>();
        let (sc, sr) = inv_v_scale.as_chunks::<LANES>();
        let (ac, ar) = a.as_chunks::<LANES>();
        let (nc, nr) = v_new.as_chunks_mut::<LANES>();
        let (mc, mr) = v_mid.as_chunks_mut::<LANES>();
        for ((((v, s), a), vn), vm) in vc.iter().zip(sc).zip(ac).zip(nc).zip(mc) {
            for l in 0..LANES {
                acc.push(l, one(v[l], s[l], h, a[l], &mut vn[l], &mut vm[l]));
            }
        }
        for (l, ((((v, s), a), vn), vm)) in vr.iter().zip(sr).zip(ar).zip(nr).zip(mr).enumerate() {
            acc.push(l, one(*v, *s, h, *a, vn, vm));
        }
        acc.finish()
    }
}

crate::sim::simd::multiversion! {
    /// Verlet's last pass (eq. 7h, 9): `x_new = x_half + h/2 v_new` and the unscaled
    /// embedded-Euler error `error = x + h v − x_new`, which the system may trim
    /// ([`SecondOrderSystem::absorbed_error`]) before [`scaled_max_abs`] takes its norm (eq. 11).
    #[allow(clippy::too_many_arguments)]
    fn verlet_finish(
        x: &[f32],
        v: &[f32],
        x_half: &[f32],
        v_new: &[f32],
        half: f32,
        h: f32,
        x_new: &mut [f32],
        error: &mut [f32],
    ) {
        for (((x, v), (x_half, v_new)), (x_new, error)) in x
            .iter()
            .zip(v)
            .zip(x_half.iter().zip(v_new))
            .zip(x_new.iter_mut().zip(error.iter_mut()))
        {
            let xn = x_half + half * v_new;
            *x_new = xn;
            *error = (x + h * v) - xn;
        }
    }
}

crate::sim::simd::multiversion! {
    /// The scaled ∞-norm of eq. 8 and 11: `max |error| / max(|x|, r_thr)` (NaN or ∞ when any
    /// term is).
    fn scaled_max_abs(x: &[f32], error: &[f32], r_thr: f32) -> f32 {
        use crate::sim::simd::{LANES, MaxLanes};
        #[inline(always)]
        fn one(x: f32, e: f32, r_thr: f32) -> f32 {
            e.abs() / x.abs().max(r_thr)
        }
        let mut acc = MaxLanes::new();
        let (xc, xr) = x.as_chunks::<LANES>();
        let (ec, er) = error.as_chunks::<LANES>();
        for (x, e) in xc.iter().zip(ec) {
            for l in 0..LANES {
                acc.push(l, one(x[l], e[l], r_thr));
            }
        }
        for (l, (x, e)) in xr.iter().zip(er).enumerate() {
            acc.push(l, one(*x, *e, r_thr));
        }
        acc.finish()
    }
}
