//! Simulation: the deformation models behind one interface, and the integrators they share.
//!
//! # The seam ([`DeformationModel`])
//! Both deformation models (the LEMAN elastic surface layer model in [`surface`], and later the
//! control lattice) implement [`DeformationModel`]. The app, the baker, `leman simulate` and the
//! tools only ever talk to this trait:
//! - drive: [`DeformationModel::advance`] to a target simulation time, given a [`PoseSource`]
//!   (the skeleton posture at any simulation time: a motion, IK or a tool edit) and a
//!   [`StepBudget`] asked before every step attempt ("may I take another step?") so the frame
//!   scheduler keeps control of wall-clock time. It returns an [`AdvanceReport`]. `advance`
//!   lands on its target; [`DeformationModel::advance_past`] keeps the step control's own
//!   steps and may stop up to one step past it (the workstation's frames, which draw the skin
//!   at the frame's time with [`DeformationModel::surface_mesh_at_into`], and
//!   `leman simulate --free-steps`).
//! - read: [`DeformationModel::surface_mesh_into`] fills a [`SurfaceMesh`] (positions, normals,
//!   triangle indices; always finite), [`DeformationModel::surface_mesh_at_into`] the same at a
//!   time within the last step.
//! - edit: [`DeformationModel::apply`] takes a [`ParameterChange`] between steps.
//! - save: [`DeformationModel::snapshot`] / [`DeformationModel::restore`] (blow-up guard, undo,
//!   baking), [`DeformationModel::set_resolution`].
//!
//! # Timing
//! The models are pure: they never read a clock themselves. Per-phase timing is optional
//! instrumentation: pass `Some(clock)` (any [`Clock`]: real in `leman simulate` and the app, a
//! [`crate::clock::VirtualClock`] in tests) and the report's [`PhaseTimes`] are filled from it;
//! pass `None` and they stay zero (and no clock is read at all).

pub mod ode;
pub mod simd;
pub mod surface;

use std::any::Any;
use std::sync::Arc;
use std::time::Duration;

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::character::{Posture, Sym2};
use crate::clock::Clock;
pub use ode::{IntegratorKind, Tolerances};

/// The skeleton posture at any simulation time: the only input that drives a deformation model.
pub trait PoseSource {
    /// Writes the posture at simulation time `time_s` into `out` (reuse its storage).
    fn posture_at(&mut self, time_s: f64, out: &mut Posture);
}

/// A [`PoseSource`] that plays a keyed motion.
#[derive(Debug, Clone, Copy)]
pub struct MotionPoses<'a>(pub &'a crate::character::Motion);

impl PoseSource for MotionPoses<'_> {
    fn posture_at(&mut self, time_s: f64, out: &mut Posture) {
        self.0.posture_at_into(time_s, out);
    }
}

/// A [`PoseSource`] that holds one posture (e.g. the current edit or IK result).
#[derive(Debug, Clone, PartialEq)]
pub struct FixedPosture(pub Posture);

impl PoseSource for FixedPosture {
    fn posture_at(&mut self, _time_s: f64, out: &mut Posture) {
        out.clone_from(&self.0);
    }
}

impl<F: FnMut(f64, &mut Posture)> PoseSource for F {
    fn posture_at(&mut self, time_s: f64, out: &mut Posture) {
        self(time_s, out);
    }
}

/// Asked before every step attempt (accepted or not): may the model take another one? The
/// frame scheduler answers from its clock; `leman simulate` and the baker use [`Unlimited`].
pub trait StepBudget {
    /// True to allow one more step attempt.
    fn may_step(&mut self) -> bool;
}

impl<F: FnMut() -> bool> StepBudget for F {
    fn may_step(&mut self) -> bool {
        self()
    }
}

/// A budget that always allows another step.
#[derive(Debug, Clone, Copy, Default)]
pub struct Unlimited;

impl StepBudget for Unlimited {
    fn may_step(&mut self) -> bool {
        true
    }
}

/// A budget of at most `n` step attempts.
#[derive(Debug, Clone, Copy)]
pub struct MaxAttempts(pub u64);

impl StepBudget for MaxAttempts {
    fn may_step(&mut self) -> bool {
        if self.0 == 0 {
            false
        } else {
            self.0 -= 1;
            true
        }
    }
}

/// Wall-clock time spent per phase (zero when no clock was passed).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct PhaseTimes {
    /// Force evaluation (elastic, tissue, gravity, damping).
    pub force: Duration,
    /// Non-penetration constraints (inside/outside tests, projections, velocity correction).
    pub constraints: Duration,
    /// Everything else (integrator arithmetic, skeleton poses, guards, bookkeeping).
    pub other: Duration,
}

impl PhaseTimes {
    /// Sum of the three phases.
    pub fn total(&self) -> Duration {
        self.force + self.constraints + self.other
    }

    /// Fractions `(force, constraints, other)` of the total (zeros when nothing was timed).
    pub fn fractions(&self) -> (f64, f64, f64) {
        let t = self.total().as_secs_f64();
        if t > 0.0 {
            (
                self.force.as_secs_f64() / t,
                self.constraints.as_secs_f64() / t,
                self.other.as_secs_f64() / t,
            )
        } else {
            (0.0, 0.0, 0.0)
        }
    }
}

/// How a [`DeformationModel::advance`] call ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AdvanceEnd {
    /// The target time was reached.
    ReachedTarget,
    /// The step budget said no before the target was reached (the frame's time was used up).
    BudgetSpent,
    /// The guard gave up: several attempts in a row, each a quarter of the last one down to the
    /// minimum step, were non-finite or exploding. The call returned early at the last
    /// accepted state (the steps accepted before the failures are kept; [`AdvanceReport`]'s
    /// `time_s` is where it stopped). The model stays there until a parameter, the posture or
    /// the state changes (a character whose forces are out of range stalls at every call).
    Stalled,
}

/// What one or more [`DeformationModel::advance`] calls did.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AdvanceReport {
    /// Simulation time reached, seconds.
    pub time_s: f64,
    /// How the (last) call ended.
    pub end: AdvanceEnd,
    /// Accepted steps.
    pub steps: u64,
    /// Rejected attempts for any reason (error control, constraints, guard).
    pub rejected_steps: u64,
    /// Of those, rejected because a constraint correction exceeded ε_c.
    pub constraint_rejections: u64,
    /// Accepted steps taken at the minimum step despite their error or constraint correction.
    pub forced_steps: u64,
    /// Smallest accepted step, seconds (`f64::INFINITY` when no step was accepted).
    pub min_step_s: f64,
    /// Largest accepted step, seconds (0 when no step was accepted).
    pub max_step_s: f64,
    /// Force evaluations with positions (each also evaluates velocity forces).
    pub force_evals: u64,
    /// Extra velocity-only force evaluations (Verlet's fixed-point iterations).
    pub velocity_evals: u64,
    /// Largest constraint correction applied on an accepted step, metres (how deep a point of
    /// the fat layer had got inside a muscle before it was pushed out). It can exceed ε_c: the
    /// rejection test limits each position component of a correction (paper 4.2.3), and a
    /// forced step is accepted whatever its correction.
    pub max_penetration_m: f32,
    /// Skin points the constraint phase pushed out of a muscle, summed over the accepted steps
    /// (a point counts once per step however many passes moved it). Divided by `steps`, the
    /// points in contact per step: what the constraint phase's cost grows with.
    pub pushed_points: u64,
    /// Skin points resting on a muscle that holds them for the next step (see
    /// [`crate::character::SimulationDefaults::hold_contacts`]), summed over the accepted steps;
    /// zero with holding off or in models without contacts.
    pub held_points: u64,
    /// Non-finite states or energy explosions caught (the step was rejected and, if the state
    /// itself was bad, the last good state restored).
    pub nonfinite_events: u64,
    /// Constraint phases run (one per attempt that passed the error test and the guard:
    /// accepted steps and constraint rejections). Zero for models without a constraint phase.
    pub constraint_phases: u64,
    /// Re-check passes the constraint phases made after their full pass (passes over the
    /// neighbourhoods of large corrections, whose normals turned; in the surface model at
    /// most [`surface::MAX_RECHECK_PASSES`] per phase).
    pub recheck_passes: u64,
    /// Skin points those re-check passes tested, summed over the passes. Against the free
    /// points each full pass tests, this is the share of the constraint work the re-checks add.
    pub rechecked_points: u64,
    /// Constraint phases whose re-check passes stopped at their limit while still correcting
    /// (fat points may be left inside a muscle by up to about a correction's length, for the
    /// next step to push out).
    pub unsettled_phases: u64,
    /// Per-phase wall-clock time (zero unless a clock was passed).
    pub phases: PhaseTimes,
}

impl Default for AdvanceReport {
    fn default() -> Self {
        Self {
            time_s: 0.0,
            end: AdvanceEnd::BudgetSpent,
            steps: 0,
            rejected_steps: 0,
            constraint_rejections: 0,
            forced_steps: 0,
            min_step_s: f64::INFINITY,
            max_step_s: 0.0,
            force_evals: 0,
            velocity_evals: 0,
            max_penetration_m: 0.0,
            pushed_points: 0,
            held_points: 0,
            nonfinite_events: 0,
            constraint_phases: 0,
            recheck_passes: 0,
            rechecked_points: 0,
            unsettled_phases: 0,
            phases: PhaseTimes::default(),
        }
    }
}

impl AdvanceReport {
    /// Whether the (last) call reached its target time.
    pub fn reached_target(&self) -> bool {
        self.end == AdvanceEnd::ReachedTarget
    }

    /// Mean skin points pushed out per accepted step (`None` before the first step).
    pub fn pushed_per_step(&self) -> Option<f64> {
        (self.steps > 0).then(|| self.pushed_points as f64 / self.steps as f64)
    }

    /// Mean skin points held on their muscles per accepted step (`None` before the first step).
    pub fn held_per_step(&self) -> Option<f64> {
        (self.steps > 0).then(|| self.held_points as f64 / self.steps as f64)
    }

    /// Mean re-check passes and re-checked points per constraint phase (`None` before the
    /// first constraint phase).
    pub fn rechecks_per_phase(&self) -> Option<(f64, f64)> {
        let phases = self.constraint_phases as f64;
        (self.constraint_phases > 0).then(|| {
            (
                self.recheck_passes as f64 / phases,
                self.rechecked_points as f64 / phases,
            )
        })
    }

    /// Adds a later report into this one (counts summed, extremes combined, time and `end`
    /// taken from `later`).
    pub fn merge(&mut self, later: &AdvanceReport) {
        self.time_s = later.time_s;
        self.end = later.end;
        self.steps += later.steps;
        self.rejected_steps += later.rejected_steps;
        self.constraint_rejections += later.constraint_rejections;
        self.forced_steps += later.forced_steps;
        self.min_step_s = self.min_step_s.min(later.min_step_s);
        self.max_step_s = self.max_step_s.max(later.max_step_s);
        self.force_evals += later.force_evals;
        self.velocity_evals += later.velocity_evals;
        self.max_penetration_m = self.max_penetration_m.max(later.max_penetration_m);
        self.pushed_points += later.pushed_points;
        self.held_points += later.held_points;
        self.nonfinite_events += later.nonfinite_events;
        self.constraint_phases += later.constraint_phases;
        self.recheck_passes += later.recheck_passes;
        self.rechecked_points += later.rechecked_points;
        self.unsettled_phases += later.unsettled_phases;
        self.phases.force += later.phases.force;
        self.phases.constraints += later.phases.constraints;
        self.phases.other += later.phases.other;
    }
}

/// The deformed surface as a triangle mesh, ready to draw. Every number is finite.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SurfaceMesh {
    /// Vertex positions in the world, metres.
    pub positions_m: Vec<Vec3>,
    /// Unit outward vertex normals.
    pub normals: Vec<Vec3>,
    /// Triangles, three vertex indices each, counter-clockwise seen from outside.
    pub indices: Vec<u32>,
}

/// Which skin points (or tissue springs) a [`ParameterChange`] touches.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Selection {
    /// Every point (or spring).
    All,
    /// These indices (skin point index `j·M + i`, or spring index).
    Some(Vec<u32>),
}

/// A parameter change applied between steps. Per-point values follow the character model's
/// units (see [`crate::character::Skin`]); they are validated and a bad value changes nothing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ParameterChange {
    /// Stretch/shear elasticity η `[η₁₁, η₁₂, η₂₂]`, N/m³.
    Stretch(Selection, Sym2),
    /// Bending resistance ξ `[ξ₁₁, ξ₁₂, ξ₂₂]`, N/m.
    Bending(Selection, Sym2),
    /// Multiplies the rest metric G⁰ (the skin's preferred size; 1.1 = 10 % looser per axis²).
    RestMetricScale(Selection, f32),
    /// Point mass, kg.
    Mass(Selection, f32),
    /// Point damping γ, N·s/m.
    Damping(Selection, f32),
    /// Fat thickness τ, metres.
    Fat(Selection, f32),
    /// Tissue spring stiffness k_s, N/m.
    TissueStiffness(Selection, f32),
    /// Tissue spring damping k_d, N·s/m.
    TissueDamping(Selection, f32),
    /// Gravity, m/s².
    Gravity(Vec3),
    /// k∥ and k⊥ of eq. 13d.
    Contact {
        /// Fraction of the normal velocity reversed (0 = inelastic).
        k_parallel: f32,
        /// Fraction of the tangential velocity kept (1 = frictionless).
        k_perpendicular: f32,
    },
    /// ε_c: largest constraint correction before a step is rejected, metres.
    ConstraintTolerance(f32),
    /// Re-check threshold of the constraint phase as a fraction of ε_c, in (0, 1] (see
    /// [`crate::character::SimulationDefaults::recheck_fraction`]).
    RecheckFraction(f32),
    /// Whether muscles hold the skin resting on them between steps (see
    /// [`crate::character::SimulationDefaults::hold_contacts`]).
    HoldContacts(bool),
    /// Switches the integrator.
    Integrator(IntegratorKind),
    /// Replaces the step-size control parameters.
    Tolerances(Tolerances),
}

/// Errors of the simulation interface.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimError {
    /// The character cannot be simulated (the message says why).
    #[error("cannot simulate this character: {0}")]
    BadCharacter(String),
    /// A parameter change was refused (the message names the parameter and value).
    #[error("parameter change refused: {0}")]
    BadParameter(String),
    /// A snapshot from another model or resolution, or with non-finite values.
    #[error("snapshot refused: {0}")]
    BadSnapshot(String),
    /// A resolution that cannot be used.
    #[error("resolution {around}×{along} refused: {reason}")]
    BadResolution {
        /// Points around.
        around: u32,
        /// Rows along.
        along: u32,
        /// Why.
        reason: String,
    },
}

/// A saved model state. Opaque and cheap to clone; only the model that made it can restore it.
#[derive(Clone)]
pub struct Snapshot {
    /// The model kind that made it (e.g. `"surface"`).
    pub model: &'static str,
    /// Simulation time of the state, seconds.
    pub time_s: f64,
    data: Arc<dyn Any + Send + Sync>,
}

impl std::fmt::Debug for Snapshot {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Snapshot")
            .field("model", &self.model)
            .field("time_s", &self.time_s)
            .finish_non_exhaustive()
    }
}

impl Snapshot {
    /// Wraps a model's state (for model implementations).
    pub fn new<T: Any + Send + Sync>(model: &'static str, time_s: f64, data: T) -> Self {
        Self {
            model,
            time_s,
            data: Arc::new(data),
        }
    }

    /// The model's state, if it is of type `T` (for model implementations).
    pub fn data<T: Any>(&self) -> Option<&T> {
        self.data.downcast_ref::<T>()
    }
}

/// Times closer than this are the same simulation time, seconds: [`DeformationModel::advance`]
/// treats a target within it as reached (so rounding in a sum of step sizes never asks for a
/// step of a few attoseconds).
pub const TIME_RESOLUTION_S: f64 = 1e-9;

/// The one interface both deformation models implement (see the module docs).
pub trait DeformationModel {
    /// Short name of the model kind (`"surface"`, `"lattice"`).
    fn model_name(&self) -> &'static str;

    /// Current simulation time, seconds.
    fn time_s(&self) -> f64;

    /// Advances towards `target_time_s`, asking `budget` before every step attempt, with the
    /// skeleton from `poses`. Stops at the target (the last step is shortened to land on it),
    /// when the budget says no, or when the guard gives up (see [`AdvanceEnd`]). `clock`, when
    /// given, is read only to fill the report's phase times. Never leaves a non-finite state
    /// behind.
    fn advance(
        &mut self,
        target_time_s: f64,
        poses: &mut dyn PoseSource,
        budget: &mut dyn StepBudget,
        clock: Option<&dyn Clock>,
    ) -> AdvanceReport;

    /// Like [`advance`](Self::advance), but the steps keep the size the step control chose
    /// instead of being shortened to land on `target_time_s`: the call ends at the first
    /// accepted step that reaches the target, which may pass it by up to one step, though never
    /// past `end_time_s` (a step that would is shortened to land there, as `advance` lands on
    /// its target). For callers that keep up with a moving target: a headless run paced in
    /// slices, or a frame loop that draws the state at each frame's time with
    /// [`surface_mesh_at_into`](Self::surface_mesh_at_into). Landing on every slice or frame
    /// costs steps (`leman simulate --free-steps` in `docs/simulate.md`).
    /// `advance_past(t, t, …)` is `advance(t, …)`. The report's `time_s` says where the call
    /// stopped.
    ///
    /// The default lands on the target, which also reaches it.
    fn advance_past(
        &mut self,
        target_time_s: f64,
        end_time_s: f64,
        poses: &mut dyn PoseSource,
        budget: &mut dyn StepBudget,
        clock: Option<&dyn Clock>,
    ) -> AdvanceReport {
        let _ = end_time_s;
        self.advance(target_time_s, poses, budget, clock)
    }

    /// Writes the deformed surface into `out` (reusing its storage).
    fn surface_mesh_into(&self, out: &mut SurfaceMesh);

    /// Writes the surface as it is drawn at `time_s` into `out`: after an
    /// [`advance_past`](Self::advance_past) that stepped past the frame's time, interpolated
    /// linearly between the states before and after the step that reached the target (the
    /// normals from the interpolated positions). Clamped to those two states: a time at or
    /// after the current one draws the current state. Without a step to interpolate over (at
    /// the start, after a restore or a resolution change), and by default, the current state.
    fn surface_mesh_at_into(&self, time_s: f64, out: &mut SurfaceMesh) {
        let _ = time_s;
        self.surface_mesh_into(out);
    }

    /// Applies a parameter change (takes effect at the next step).
    fn apply(&mut self, change: &ParameterChange) -> Result<(), SimError>;

    /// The current state: positions, velocities, time, step size, and every parameter
    /// [`apply`](Self::apply) can change (materials, contact and solver settings, the
    /// integrator). Restoring it continues exactly as the model went on from it, which undo and
    /// baking need. A caller that shows these settings (the workstation's panel) and wants its
    /// current values to win applies them again after a restore.
    fn snapshot(&self) -> Snapshot;

    /// Returns to a state made by [`snapshot`](Self::snapshot) of this model; a snapshot of
    /// another model or resolution is refused and nothing changes.
    fn restore(&mut self, snapshot: &Snapshot) -> Result<(), SimError>;

    /// `(around, along)` resolution of the surface.
    fn resolution(&self) -> (u32, u32);

    /// Resamples the model to a new resolution (LEMAN 6.5: bilinear interpolation of every
    /// per-point value).
    fn set_resolution(&mut self, around: u32, along: u32) -> Result<(), SimError>;

    /// Number of simulated surface points (for cost measures such as point-steps per second).
    fn point_count(&self) -> usize;
}
