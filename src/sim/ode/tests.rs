use super::*;

/// `x'' = −ω² x − c x'` on `n` independent copies.
struct Oscillator {
    omega: f32,
    c: f32,
    n: usize,
}

impl SecondOrderSystem for Oscillator {
    fn dofs(&self) -> usize {
        self.n
    }
    fn position_accel(&mut self, _t: f64, x: &[f32], a: &mut [f32]) {
        for (a, x) in a.iter_mut().zip(x) {
            *a = -self.omega * self.omega * x;
        }
    }
    fn add_velocity_accel(&mut self, _t: f64, _x: &[f32], v: &[f32], a: &mut [f32]) {
        for (a, v) in a.iter_mut().zip(v) {
            *a -= self.c * v;
        }
    }
    fn has_velocity_forces(&self) -> bool {
        self.c != 0.0
    }
}

/// Exact solution of the damped oscillator with x(0)=1, x'(0)=0 (underdamped).
fn exact(omega: f64, c: f64, t: f64) -> f64 {
    let zeta_omega = 0.5 * c;
    let omega_d = (omega * omega - zeta_omega * zeta_omega).sqrt();
    (-zeta_omega * t).exp() * ((omega_d * t).cos() + zeta_omega / omega_d * (omega_d * t).sin())
}

/// Its velocity.
fn exact_velocity(omega: f64, c: f64, t: f64) -> f64 {
    let zeta_omega = 0.5 * c;
    let omega_d = (omega * omega - zeta_omega * zeta_omega).sqrt();
    -(-zeta_omega * t).exp() * (omega_d + zeta_omega * zeta_omega / omega_d) * (omega_d * t).sin()
}

/// Tolerances that force a fixed step `h` for every method.
fn fixed_step(h: f64) -> Tolerances {
    Tolerances {
        euler_step_s: h,
        rk4_step_s: h,
        min_step_s: h,
        max_step_s: h,
        velocity_tolerance: 1e-7,
        max_velocity_iterations: 50,
        ..Tolerances::default()
    }
}

fn error_at(kind: IntegratorKind, h: f64, c: f32, t_end: f64) -> f64 {
    let mut sys = Oscillator {
        omega: 1.0,
        c,
        n: 1,
    };
    let mut integ = Integrator::new(kind, fixed_step(h));
    let mut x = [1.0f32];
    let mut v = [0.0f32];
    integrate(&mut integ, &mut sys, 0.0, t_end, &mut x, &mut v);
    let ex = f64::from(x[0]) - exact(1.0, f64::from(c), t_end);
    let ev = f64::from(v[0]) - exact_velocity(1.0, f64::from(c), t_end);
    ex.hypot(ev)
}

/// Observed order from errors with `steps`, 2×`steps` and 4×`steps` equal steps up to
/// t = 2.3 s (not a whole period, 2π s): the mean of the two ratios' log2.
fn observed_order(kind: IntegratorKind, steps: u32, c: f32) -> f64 {
    let t_end = 2.3;
    let h = t_end / f64::from(steps);
    let e1 = error_at(kind, h, c, t_end);
    let e2 = error_at(kind, h / 2.0, c, t_end);
    let e3 = error_at(kind, h / 4.0, c, t_end);
    ((e1 / e2).log2() + (e2 / e3).log2()) / 2.0
}

#[test]
fn euler_is_first_order() {
    let p = observed_order(IntegratorKind::Euler, 100, 0.0);
    assert!((0.85..1.15).contains(&p), "Euler order {p}");
    let p = observed_order(IntegratorKind::Euler, 100, 0.3);
    assert!((0.85..1.15).contains(&p), "damped Euler order {p}");
}

#[test]
fn verlet_is_second_order_with_and_without_velocity_forces() {
    let p = observed_order(IntegratorKind::Verlet, 40, 0.0);
    assert!((1.85..2.15).contains(&p), "Verlet order {p}");
    let p = observed_order(IntegratorKind::Verlet, 40, 0.3);
    assert!((1.85..2.15).contains(&p), "damped Verlet order {p}");
}

#[test]
fn rk2_is_second_order() {
    let p = observed_order(IntegratorKind::Rk2, 40, 0.3);
    assert!((1.85..2.15).contains(&p), "RK2 order {p}");
}

#[test]
fn rk4_is_fourth_order() {
    // Large steps so the f32 round-off floor stays far below the truncation error.
    let p = observed_order(IntegratorKind::Rk4, 4, 0.3);
    assert!((3.7..4.3).contains(&p), "RK4 order {p}");
}

/// What [`GuessingOscillator`] offers the Verlet iteration as its start.
#[derive(Clone, Copy, PartialEq, Debug)]
enum Start {
    /// No estimate: the paper's start from `v_t`.
    None,
    /// The exact fixed point of `v⁺ = v + h (a_pos − c (v + v⁺)/2)`.
    Exact,
    /// A wrong estimate (off by 3 m/s).
    Wrong,
}

/// [`Oscillator`] that offers the Verlet velocity iteration a start.
struct GuessingOscillator {
    inner: Oscillator,
    start: Start,
}

impl SecondOrderSystem for GuessingOscillator {
    fn dofs(&self) -> usize {
        self.inner.dofs()
    }
    fn position_accel(&mut self, t: f64, x: &[f32], a: &mut [f32]) {
        self.inner.position_accel(t, x, a);
    }
    fn add_velocity_accel(&mut self, t: f64, x: &[f32], v: &[f32], a: &mut [f32]) {
        self.inner.add_velocity_accel(t, x, v, a);
    }
    fn velocity_fixed_point(
        &mut self,
        _t_s: f64,
        _x: &[f32],
        v: &[f32],
        a_pos: &[f32],
        h_s: f64,
        v_new: &mut [f32],
    ) -> bool {
        let (h, c) = (h_s as f32, self.inner.c);
        for ((n, v), a) in v_new.iter_mut().zip(v).zip(a_pos) {
            *n = match self.start {
                Start::None => return false,
                Start::Exact => ((2.0 - h * c) * v + 2.0 * h * a) / (2.0 + h * c),
                Start::Wrong => v + 3.0,
            };
        }
        true
    }
}

/// The damped oscillator over 200 Verlet steps of 0.05 s from `start`: the final state and
/// the velocity evaluations per step.
fn verlet_from(start: Start) -> ([f32; 2], f64) {
    let h = 0.05;
    let mut sys = GuessingOscillator {
        inner: Oscillator {
            omega: 1.0,
            c: 4.0,
            n: 1,
        },
        start,
    };
    let tolerances = Tolerances {
        velocity_tolerance: 1e-6,
        ..fixed_step(h)
    };
    let mut integ = Integrator::new(IntegratorKind::Verlet, tolerances);
    let (mut x, mut v) = ([1.0f32], [0.0f32]);
    let (mut xn, mut vn) = ([0.0f32], [0.0f32]);
    let mut evals = 0u32;
    for i in 0..200 {
        let p = integ.propose(&mut sys, i as f64 * h, h, &x, &v, &mut xn, &mut vn);
        assert!(p.accepted, "{start:?} step {i}");
        evals += p.velocity_evals;
        x = xn;
        v = vn;
    }
    ([x[0], v[0]], f64::from(evals) / 200.0)
}

#[test]
fn a_systems_fixed_point_start_saves_velocity_evaluations_and_changes_nothing_else() {
    let (paper, paper_evals) = verlet_from(Start::None);
    let (exact, exact_evals) = verlet_from(Start::Exact);
    let (wrong, wrong_evals) = verlet_from(Start::Wrong);
    // hc/2 = 0.1: the iteration from v_t needs several evaluations to reach 1e-6.
    assert!(paper_evals >= 4.0, "{paper_evals}");
    assert_eq!(exact_evals, 1.0, "the exact start passes the first test");
    // The iteration, not the start, decides where it ends: all three end at the fixed point.
    assert!(wrong_evals > paper_evals, "{wrong_evals} vs {paper_evals}");
    for (got, name) in [(exact, "exact"), (wrong, "wrong")] {
        for k in 0..2 {
            assert!(
                (got[k] - paper[k]).abs() <= 1e-5,
                "{name}: {got:?} vs {paper:?}"
            );
        }
    }
}

fn energy(x: f32, v: f32, omega: f32) -> f32 {
    0.5 * v * v + 0.5 * omega * omega * x * x
}

#[test]
fn verlet_energy_stays_bounded_while_euler_grows_it() {
    let omega = 1.0;
    let h = 0.1;
    let run = |kind| {
        let mut sys = Oscillator {
            omega,
            c: 0.0,
            n: 1,
        };
        let mut integ = Integrator::new(kind, fixed_step(h));
        let (mut x, mut v) = ([1.0f32], [0.0f32]);
        let e0 = energy(x[0], v[0], omega);
        let mut max_dev = 0.0f32;
        let mut xn = [0.0f32];
        let mut vn = [0.0f32];
        for i in 0..10_000 {
            let p = integ.propose(&mut sys, i as f64 * h, h, &x, &v, &mut xn, &mut vn);
            assert!(p.accepted);
            x = xn;
            v = vn;
            max_dev = max_dev.max((energy(x[0], v[0], omega) / e0 - 1.0).abs());
        }
        (max_dev, energy(x[0], v[0], omega) / e0)
    };
    let (verlet_dev, _) = run(IntegratorKind::Verlet);
    assert!(verlet_dev < 0.01, "Verlet energy drifted by {verlet_dev}");
    let (_, euler_final) = run(IntegratorKind::Euler);
    // (1 + h²ω²)^n per step: grows enormously.
    assert!(euler_final > 100.0, "Euler energy ratio {euler_final}");
}

fn verlet_amplitude_after(h_omega: f32, steps: usize) -> f32 {
    let omega = 10.0f32;
    let h = f64::from(h_omega / omega);
    let mut sys = Oscillator {
        omega,
        c: 0.0,
        n: 1,
    };
    let mut integ = Integrator::new(IntegratorKind::Verlet, fixed_step(h));
    let (mut x, mut v) = ([1.0f32], [0.0f32]);
    let (mut xn, mut vn) = ([0.0f32], [0.0f32]);
    let mut max_abs = 0.0f32;
    for i in 0..steps {
        integ.propose(&mut sys, i as f64 * h, h, &x, &v, &mut xn, &mut vn);
        x = xn;
        v = vn;
        max_abs = max_abs.max(x[0].abs());
        if !max_abs.is_finite() {
            return f32::INFINITY;
        }
    }
    max_abs
}

#[test]
fn verlet_is_stable_below_h_omega_2_and_unstable_above() {
    for h_omega in [0.5f32, 1.0, 1.5, 1.9, 1.98] {
        let amp = verlet_amplitude_after(h_omega, 5000);
        // Leapfrog keeps |x| bounded by a constant depending on hω (≤ 1/sqrt(1 − (hω/2)²)).
        let bound = 1.0 / (1.0 - (h_omega / 2.0).powi(2)).sqrt() * 1.05;
        assert!(amp <= bound, "hω={h_omega}: amplitude {amp} > {bound}");
    }
    for h_omega in [2.02f32, 2.2, 3.0] {
        let amp = verlet_amplitude_after(h_omega, 2000);
        assert!(amp > 1e6, "hω={h_omega}: amplitude {amp} should blow up");
    }
}

#[test]
fn adaptive_methods_meet_tighter_tolerances_with_smaller_steps() {
    for kind in [IntegratorKind::Verlet, IntegratorKind::Rk2] {
        let mut errs = Vec::new();
        let mut steps = Vec::new();
        for tol in [1e-3, 1e-4, 1e-5] {
            let mut sys = Oscillator {
                omega: 1.0,
                c: 0.3,
                n: 1,
            };
            let t = Tolerances {
                euler_step_s: 0.5,
                min_step_s: 1e-4,
                max_step_s: 1.0,
                position_tolerance: tol,
                velocity_tolerance: 1e-7,
                max_velocity_iterations: 50,
                ..Tolerances::default()
            };
            let mut integ = Integrator::new(kind, t);
            let (mut x, mut v) = ([1.0f32], [0.0f32]);
            let s = integrate(&mut integ, &mut sys, 0.0, 2.3, &mut x, &mut v);
            assert!(
                s.rejected > 0,
                "{kind:?}: an initial 0.5 s step must be rejected"
            );
            errs.push((f64::from(x[0]) - exact(1.0, 0.3, 2.3)).abs());
            steps.push(s.accepted);
        }
        assert!(errs[2] < errs[0], "{kind:?}: errors {errs:?}");
        assert!(
            steps[0] < steps[1] && steps[1] < steps[2],
            "{kind:?}: steps {steps:?}"
        );
    }
}

#[test]
fn length_mismatch_is_rejected_not_a_panic() {
    let mut sys = Oscillator {
        omega: 1.0,
        c: 0.0,
        n: 2,
    };
    let mut integ = Integrator::new(IntegratorKind::Verlet, Tolerances::default());
    let (x, v) = ([1.0f32], [0.0f32]);
    let (mut xn, mut vn) = ([0.0f32], [0.0f32]);
    let p = integ.propose(&mut sys, 0.0, 0.01, &x, &v, &mut xn, &mut vn);
    assert!(!p.accepted);
}

#[test]
fn names_round_trip() {
    for k in IntegratorKind::ALL {
        assert_eq!(IntegratorKind::from_name(k.name()), Some(k));
    }
    assert_eq!(IntegratorKind::from_name("leapfrog"), None);
}

/// A point `(x, y)` (state `[x, y]`) under a constant acceleration `(ax, ay)`, with a floor at
/// `y = 0` that the harness ([`run_on_floor`]) enforces after each accepted step, as a model's
/// constraint pass would. When `contact_aware`, the error hook drops the inward (−y) part of
/// the error while the point touched the floor after the last accepted step.
struct OnFloor {
    accel: [f32; 2],
    contact_aware: bool,
    in_contact: bool,
}

impl OnFloor {
    fn new(accel: [f32; 2], contact_aware: bool) -> Self {
        Self {
            accel,
            contact_aware,
            in_contact: false,
        }
    }
}

impl SecondOrderSystem for OnFloor {
    fn dofs(&self) -> usize {
        2
    }
    fn position_accel(&mut self, _t: f64, _x: &[f32], a: &mut [f32]) {
        a.copy_from_slice(&self.accel);
    }
    fn add_velocity_accel(&mut self, _t: f64, _x: &[f32], _v: &[f32], _a: &mut [f32]) {}
    fn has_velocity_forces(&self) -> bool {
        false
    }
    fn absorbed_error(&self, _x: &[f32], error: &mut [f32]) {
        // Outward normal (0, 1): e·n > 0 means the step went further into the floor than
        // Euler's; the floor constraint replaces that part.
        if self.contact_aware && self.in_contact && error[1] > 0.0 {
            error[1] = 0.0;
        }
    }
}

/// Tolerances of a character file (ε_r scaled down so the uncorrected estimate clearly limits
/// the step): steps between 0.5 and 16 ms.
fn floor_tolerances() -> Tolerances {
    Tolerances {
        euler_step_s: 0.004,
        min_step_s: 0.000_5,
        max_step_s: 0.016,
        position_tolerance: 1.0e-4,
        ..Tolerances::default()
    }
}

/// Runs `sys` from `(x, v)` for `seconds`, projecting the point onto the floor after each
/// accepted step (`y < 0` → `y = 0`, downward velocity removed) and telling the system whether
/// it touched. Returns the accepted steps after the first `settle_s` seconds and the
/// number of rejections.
fn run_on_floor(
    kind: IntegratorKind,
    sys: &mut OnFloor,
    mut x: [f32; 2],
    mut v: [f32; 2],
    seconds: f64,
    settle_s: f64,
) -> (Vec<f64>, u32, [f32; 2]) {
    let mut integ = Integrator::new(kind, floor_tolerances());
    let (mut xn, mut vn) = ([0.0f32; 2], [0.0f32; 2]);
    let mut t = 0.0;
    let mut h = integ.initial_step_s();
    let mut steps = Vec::new();
    let mut rejected = 0;
    while t < seconds {
        let p = integ.propose(sys, t, h, &x, &v, &mut xn, &mut vn);
        if !p.accepted {
            rejected += 1;
            h = p.next_step_s;
            continue;
        }
        x = xn;
        v = vn;
        sys.in_contact = x[1] < 0.0;
        if sys.in_contact {
            x[1] = 0.0;
            v[1] = v[1].max(0.0);
        }
        t += h;
        if t > settle_s {
            steps.push(h);
        }
        h = p.next_step_s;
    }
    (steps, rejected, x)
}

#[test]
fn contact_aware_error_lets_a_resting_point_take_the_largest_step() {
    let gravity = [0.0, -9.81];
    for kind in [IntegratorKind::Verlet, IntegratorKind::Rk2] {
        // The uncorrected estimate counts the fall into the floor, h² g / 2 ≤ ε_r:
        // h ≤ sqrt(2 ε_r / g) ≈ 4.5 ms whatever the floor does.
        let mut plain = OnFloor::new(gravity, false);
        let (steps, _, x) = run_on_floor(kind, &mut plain, [0.0, 0.0], [0.0; 2], 2.0, 0.5);
        let largest = steps.iter().copied().fold(0.0, f64::max);
        assert!(largest < 0.005, "{kind:?} without the hook: step {largest}");
        assert_eq!(x[1], 0.0, "{kind:?}: the point rests on the floor");
        // With the hook the inward error is the floor's business: steps reach max_step_s.
        let mut aware = OnFloor::new(gravity, true);
        let (steps, rejected, x) = run_on_floor(kind, &mut aware, [0.0, 0.0], [0.0; 2], 2.0, 0.5);
        let smallest = steps.iter().copied().fold(f64::INFINITY, f64::min);
        assert!(
            smallest >= 0.016 * (1.0 - 1e-9),
            "{kind:?} with the hook: step {smallest} (rejected {rejected})"
        );
        assert_eq!(rejected, 0, "{kind:?}");
        assert_eq!(x[1], 0.0, "{kind:?}: the point rests on the floor");
    }
}

#[test]
fn contact_aware_error_keeps_the_full_estimate_off_the_floor() {
    // Falling freely from 1 m (no contact in 0.4 s; positions below r_thr, so the error is
    // absolute): the hook must change nothing.
    for kind in [IntegratorKind::Verlet, IntegratorKind::Rk2] {
        let run = |aware| {
            let mut sys = OnFloor::new([0.0, -9.81], aware);
            run_on_floor(kind, &mut sys, [0.0, 1.0], [0.0; 2], 0.4, 0.0)
        };
        let (with_hook, rej_a, x_a) = run(true);
        let (without, rej_b, x_b) = run(false);
        assert_eq!(with_hook, without, "{kind:?}");
        assert_eq!((rej_a, x_a), (rej_b, x_b), "{kind:?}");
        assert!(x_a[1] > 0.0, "{kind:?}: still above the floor");
        assert!(with_hook.iter().all(|h| *h < 0.005), "{kind:?}");
    }
}

#[test]
fn contact_aware_error_drops_only_the_inward_part() {
    // One proposal from a point on the floor (in contact), sliding with a sideways
    // acceleration: the error ratio keeps the sideways part and drops the downward part,
    // and an outward (upward) acceleration is not dropped at all.
    let h = 0.01;
    let ratio = |kind, accel: [f32; 2], aware| {
        let mut sys = OnFloor::new(accel, aware);
        sys.in_contact = true;
        let mut integ = Integrator::new(kind, floor_tolerances());
        let (mut xn, mut vn) = ([0.0f32; 2], [0.0f32; 2]);
        integ
            .propose(&mut sys, 0.0, h, &[0.0, 0.0], &[0.1, 0.0], &mut xn, &mut vn)
            .error_ratio
    };
    for kind in [IntegratorKind::Verlet, IntegratorKind::Rk2] {
        let tol = floor_tolerances().position_tolerance;
        let expect = |a: f64| 0.5 * h * h * a / tol;
        // Down 9.81, sideways 2: only the sideways error is left.
        let r = ratio(kind, [2.0, -9.81], true);
        assert!(
            (r - expect(2.0)).abs() < 1e-3 * expect(2.0),
            "{kind:?}: {r}"
        );
        let r = ratio(kind, [2.0, -9.81], false);
        assert!(
            (r - expect(9.81)).abs() < 1e-3 * expect(9.81),
            "{kind:?}: {r}"
        );
        // Up 9.81 (away from the floor): the full error counts.
        let r = ratio(kind, [2.0, 9.81], true);
        assert!(
            (r - expect(9.81)).abs() < 1e-3 * expect(9.81),
            "{kind:?}: {r}"
        );
    }
}

#[test]
fn tolerances_out_of_range_are_named() {
    assert_eq!(Tolerances::default().check(), Ok(()));
    type Spoil = fn(&mut Tolerances);
    let cases: [(Spoil, &str); 13] = [
        (|t| t.min_step_s = 0.0, "min_step_s"),
        // Finite in f64 but not in the simulator's f32.
        (|t| t.max_step_s = 1e300, "max_step_s"),
        (|t| t.velocity_tolerance = 1e-300, "velocity_tolerance"),
        (|t| t.position_tolerance = f64::NAN, "position_tolerance"),
        (|t| t.euler_step_s = f64::INFINITY, "euler_step_s"),
        (|t| t.rk4_step_s = 0.0, "rk4_step_s"),
        (|t| t.max_step_s = 1e-5, "below min_step_s"),
        (|t| t.safety = 1.5, "safety"),
        (|t| t.max_shrink = 1.0, "max_shrink"),
        // Growth below shrink made the controller's clamp panic before this check.
        (
            |t| (t.max_growth, t.max_shrink) = (1e-30, 1e-8),
            "max_growth",
        ),
        (|t| t.max_growth = -2.0, "max_growth"),
        // u32::MAX iterations kept an attempt running for hours.
        (
            |t| t.max_velocity_iterations = u32::MAX,
            "max_velocity_iterations",
        ),
        (|t| t.max_velocity_iterations = 0, "max_velocity_iterations"),
    ];
    for (spoil, name) in cases {
        let mut t = Tolerances::default();
        spoil(&mut t);
        let err = t.check().expect_err(name);
        assert!(err.contains(name), "{name}: {err}");
    }
}

#[test]
fn the_fixed_step_methods_each_take_their_own_step() {
    let t = Tolerances {
        euler_step_s: 0.001,
        rk4_step_s: 0.004,
        ..Tolerances::default()
    };
    let mut sys = Oscillator {
        omega: 1.0,
        c: 0.0,
        n: 1,
    };
    for (kind, want) in [(IntegratorKind::Euler, 0.001), (IntegratorKind::Rk4, 0.004)] {
        assert_eq!(t.fixed_step_s(kind), want, "{kind:?}");
        let mut integ = Integrator::new(kind, t);
        assert_eq!(integ.initial_step_s(), want, "{kind:?}");
        let (mut xn, mut vn) = ([0.0f32], [0.0f32]);
        let p = integ.propose(&mut sys, 0.0, want, &[1.0], &[0.0], &mut xn, &mut vn);
        assert!(p.accepted, "{kind:?}");
        assert_eq!(p.next_step_s, want, "{kind:?}");
    }
}
