//! The LEMAN elastic surface layer model (skin over muscles, fat and connective tissue),
//! paper `003_…` sections 3-4: [`SurfaceModel`] implements [`DeformationModel`].
//!
//! One step (see [`SurfaceModel::advance`]):
//! 1. Skeleton at the end of the attempted step: posture from the [`PoseSource`], forward
//!    kinematics, shape instances, fixed rows and tissue anchors (the start values are the
//!    previous step's end; in between they are interpolated linearly, see
//!    [`forces::StepKinematics`]).
//! 2. The integrator proposes a candidate state ([`crate::sim::ode`]); its error control may
//!    reject it (retry with its smaller step).
//! 3. Guard: a non-finite candidate or an exploding kinetic energy rejects the step (retry with a
//!    quarter step); a non-finite committed state (which should never happen) is replaced by the
//!    last good checkpoint.
//! 4. Constraints ([`constraints`]) push fat points out of muscles; a correction component larger
//!    than ε_c rejects the step and retries with a smaller step chosen by false position on the
//!    bracket `[0, h]` (the correction grows about linearly with the step), down to the minimum
//!    step where it is accepted (counted as forced).
//! 5. Commit (buffer swap, no copy).

#![allow(clippy::needless_range_loop)] // index loops over parallel SoA arrays read best as they are

mod anchors;
pub mod constraints;
mod contacts;
mod fastmath;
pub mod forces;
pub(crate) mod kernels;
mod masks;
mod moves;
mod resample;
#[cfg(test)]
mod tests;

use std::sync::Arc;
use std::time::Duration;

use glam::Vec3;

use super::ode::{Integrator, IntegratorKind, SecondOrderSystem, Tolerances};
use super::{
    AdvanceEnd, AdvanceReport, DeformationModel, ParameterChange, PoseSource, Selection, SimError,
    Snapshot, StepBudget, SurfaceMesh, TIME_RESOLUTION_S,
};
use crate::character::{Character, Posture, ShapeInstance, SimulationDefaults, SkeletonPose};
use crate::clock::Clock;
use anchors::AnchorTable;
use constraints::{Broadphase, ConstraintInput};
use contacts::{ContactState, PhaseEnd, UpdateScratch};
use forces::{ForceInput, ForceScratch, Materials, Springs, StepKinematics};

/// Name of this model kind in snapshots and reports.
pub const MODEL_NAME: &str = "surface";

/// Reference speed of the energy guard: a candidate whose kinetic energy exceeds ten times the
/// previous one plus that of the whole skin moving at this speed is an explosion.
const GUARD_SPEED_M_PER_S: f64 = 5.0;

/// The persistent state: everything a snapshot holds.
#[derive(Debug, Clone)]
struct Core {
    character: Arc<Character>,
    around: usize,
    along: usize,
    /// Row 0 in the bottom joint's frame and row N−1 in the top joint's frame (M each).
    bottom_ring_m: Vec<Vec3>,
    top_ring_m: Vec<Vec3>,
    t_s: f64,
    step_s: f64,
    x: Vec<f32>,
    v: Vec<f32>,
    materials: Materials,
    springs: Springs,
    /// The springs' anchors grouped by shape, for placing them each step.
    anchor_table: AnchorTable,
    kind: IntegratorKind,
    tolerances: Tolerances,
    k_parallel: f32,
    k_perpendicular: f32,
    epsilon_c_m: f32,
    /// Corrections longer than this fraction of ε_c send their neighbourhoods to the re-checks.
    recheck_fraction: f32,
    /// The points the constraint phase pushed in the last committed step and the ones it
    /// pushed before that a muscle still holds ([`contacts`]): the next step's error estimate
    /// leaves their inward error to the constraints ([`SecondOrderSystem::absorbed_error`]),
    /// and the holding ones lose the acceleration into their muscle. Part of the state, so a
    /// snapshot or checkpoint continues exactly as the run it was taken from.
    contacts: ContactState,
    /// Whether muscles hold the skin resting on them between steps ([`ContactState::hold`]);
    /// off, contact is the paper's positional projection alone.
    hold_contacts: bool,
    /// The fixed rows in the world at `t_s` (row 0 then row N−1, SoA, 2M each): the step's start
    /// whenever the skeleton has placed it ([`start_placed`]), else as restored or resampled with
    /// the grid; empty until one of those. The skin is drawn with them; only when they are empty
    /// with the neutral posture's rows (which after a restore or a resolution change would snap
    /// its ends there).
    rings_world: [Vec<f32>; 3],
}

/// Scratch and caches (not part of a snapshot).
#[derive(Debug, Clone, Default)]
struct Work {
    integrator: Option<Integrator>,
    kin: StepKinematics,
    start_valid: bool,
    shapes_start: Vec<ShapeInstance>,
    shapes_end: Vec<ShapeInstance>,
    posture: Posture,
    pose: SkeletonPose,
    x_new: Vec<f32>,
    v_new: Vec<f32>,
    force: ForceScratch,
    normals: [Vec<f32>; 3],
    broad: Broadphase,
    checkpoint_x: Vec<f32>,
    checkpoint_v: Vec<f32>,
    checkpoint_t_s: f64,
    checkpoint_step_s: f64,
    /// `Core::rings_world` at the checkpoint.
    checkpoint_rings: [Vec<f32>; 3],
    touched: Vec<u32>,
    recheck: Vec<u32>,
    /// Scratch of [`AnchorTable::place`].
    anchor_scratch: [Vec<f32>; 3],
    /// The candidate's positions before the constraint phase (SoA, free points).
    x_unconstrained: Vec<f32>,
    flags: Vec<u8>,
    /// `(t, h, correction)` of the last constraint rejection (for root bracketing).
    last_constraint_reject: Option<(f64, f64, f32)>,
    /// The contacts after the current candidate's constraint phase; promoted to
    /// `Core::contacts` only when the candidate is committed.
    candidate_contacts: ContactState,
    /// Per free point, 1 if it is among `candidate_contacts` (the points the constraint phase
    /// moved in the current candidate), else 0.
    contact_mask: Vec<u8>,
    /// `Core::contacts` at the checkpoint.
    checkpoint_contacts: ContactState,
    /// Scratch of [`ContactState::update`].
    contact_scratch: UpdateScratch,
    /// Per free point, 1 where the current candidate's full pass pushed it, with the direction
    /// (world, SoA; see [`PhaseEnd::first`]), with holding off.
    first_mask: Vec<u8>,
    first_normal: [Vec<f32>; 3],
    /// The whole grid (fixed rings included, SoA) before the last accepted step of the last
    /// `advance` call, the one that reached its target, and its time (`None` when there is
    /// none: at the start, after a restore, a resolution change or the guard's restore; the
    /// grid's storage is kept for the next one). The skin is drawn interpolated between it and
    /// the current state ([`DeformationModel::surface_mesh_at_into`]).
    drawn_before: [Vec<f32>; 3],
    drawn_before_t_s: Option<f64>,
}

/// The elastic surface layer model of one character.
#[derive(Debug, Clone)]
pub struct SurfaceModel {
    core: Core,
    work: Work,
}

/// The `SecondOrderSystem` view of the forces for one step, with optional timing.
struct Eval<'a> {
    input: ForceInput<'a>,
    scratch: &'a mut ForceScratch,
    /// Contacts of the last committed step (see [`SecondOrderSystem::absorbed_error`]).
    contacts: &'a ContactState,
    clock: Option<&'a dyn Clock>,
    force_time: Duration,
}

impl Eval<'_> {
    fn now(&self) -> Option<Duration> {
        self.clock.map(|c| c.now())
    }
    fn add_time(&mut self, since: Option<Duration>) {
        if let (Some(start), Some(c)) = (since, self.clock) {
            self.force_time += c.now().saturating_sub(start);
        }
    }
}

impl SecondOrderSystem for Eval<'_> {
    fn dofs(&self) -> usize {
        3 * self.input.around * (self.input.along - 2)
    }
    fn position_accel(&mut self, t_s: f64, x: &[f32], a: &mut [f32]) {
        let start = self.now();
        forces::position_accel(&self.input, self.scratch, t_s, x, a);
        self.contacts.hold(a);
        self.add_time(start);
    }
    fn add_velocity_accel(&mut self, _t_s: f64, _x: &[f32], v: &[f32], a: &mut [f32]) {
        let start = self.now();
        forces::add_velocity_accel(&self.input, self.scratch, v, a);
        self.add_time(start);
    }
    fn velocity_accel_from(
        &mut self,
        _t_s: f64,
        _x: &[f32],
        v: &[f32],
        a_pos: &[f32],
        a: &mut [f32],
    ) {
        let start = self.now();
        forces::velocity_accel_from(&self.input, self.scratch, v, a_pos, a);
        self.add_time(start);
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
        let start = self.now();
        let solved = forces::midpoint_velocity_fixed_point(
            &self.input,
            self.scratch,
            v,
            a_pos,
            h_s as f32,
            v_new,
        );
        self.add_time(start);
        solved
    }
    /// For each point in contact after the last step, drops the error component along the
    /// contact normal when it points into the muscle: the step went further in than Euler's,
    /// and the constraint phase replaces that motion (checked against ε_c, section 4.2.3).
    fn absorbed_error(&self, _x: &[f32], error: &mut [f32]) {
        self.contacts.drop_inward_error(error);
    }
}

fn soa(points: impl ExactSizeIterator<Item = Vec3>) -> [Vec<f32>; 3] {
    let n = points.len();
    let mut out = [
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
    ];
    for p in points {
        out[0].push(p.x);
        out[1].push(p.y);
        out[2].push(p.z);
    }
    out
}

impl SurfaceModel {
    /// A model of `character` at its skin's resolution, state at rest in the neutral posture at
    /// time 0, parameters from the character's simulation defaults.
    pub fn new(character: Character, kind: IntegratorKind) -> Result<Self, SimError> {
        character
            .validate()
            .map_err(|e| SimError::BadCharacter(e.to_string()))?;
        let core = Core::from_character(Arc::new(character), kind)?;
        let mut work = Work::default();
        work.broad.margin_m = 0.02;
        let mut model = Self { core, work };
        model.save_checkpoint();
        Ok(model)
    }

    /// The character being simulated (at its original resolution).
    pub fn character(&self) -> &Character {
        &self.core.character
    }

    /// Current integrator.
    pub fn integrator(&self) -> IntegratorKind {
        self.core.kind
    }

    /// Current step-size parameters.
    pub fn tolerances(&self) -> Tolerances {
        self.core.tolerances
    }

    /// ε_c, metres.
    pub fn epsilon_c_m(&self) -> f32 {
        self.core.epsilon_c_m
    }

    /// The step size the model will try next, seconds.
    pub fn next_step_s(&self) -> f64 {
        self.core.step_s
    }

    /// Positions of every skin point (fixed rows included, index `j·M + i`) at the current time,
    /// for a skeleton posture `posture` (which places the fixed rows).
    pub fn positions_m(&self) -> Vec<Vec3> {
        let grid = self.current_grid();
        (0..grid[0].len())
            .map(|k| Vec3::new(grid[0][k], grid[1][k], grid[2][k]))
            .collect()
    }

    /// Velocities of the free points (rows 1..N−2), m/s.
    pub fn free_velocities(&self) -> Vec<Vec3> {
        let free = self.core.free();
        (0..free)
            .map(|f| {
                Vec3::new(
                    self.core.v[f],
                    self.core.v[free + f],
                    self.core.v[2 * free + f],
                )
            })
            .collect()
    }

    /// Deepest penetration of any fat point into any muscle for the current state, metres
    /// (brute force over all points and shapes; for tests and checks).
    pub fn max_depth_m(&self) -> f32 {
        let grid = self.current_grid();
        let mut normals = Default::default();
        fat_normals(&self.core, &grid, &mut normals);
        let shapes = if self.work.start_valid {
            self.work.shapes_start.clone()
        } else {
            let mut pose = SkeletonPose::default();
            let posture = Posture::neutral(&self.core.character.skeleton);
            self.core
                .character
                .skeleton
                .forward_kinematics_into(&posture, &mut pose);
            let mut out = Vec::new();
            self.core.character.shape_instances_into(
                &posture,
                &pose,
                self.core.t_s as f32,
                &mut out,
            );
            out
        };
        constraints::max_depth_m(
            self.core.around,
            self.core.along,
            &grid,
            &normals,
            &self.core.materials.fat_m,
            &shapes,
        )
    }

    /// One force evaluation (position and velocity forces) at the current state, for benchmarks
    /// and profiling. Returns the sum of the accelerations (so the work cannot be optimised
    /// away). The skeleton comes from the last step (the neutral posture before the first).
    pub fn evaluate_forces_once(&mut self, poses: &mut dyn PoseSource) -> f32 {
        self.ensure_start(poses);
        let core = &self.core;
        let w = &mut self.work;
        w.kin.t0_s = core.t_s;
        w.kin.h_s = 0.0;
        w.kin.rings_end.clone_from(&w.kin.rings_start);
        w.kin.anchors_end.clone_from(&w.kin.anchors_start);
        let input = ForceInput {
            around: core.around,
            along: core.along,
            materials: &core.materials,
            springs: &core.springs,
            kin: &w.kin,
        };
        w.x_new.resize(core.x.len(), 0.0);
        forces::position_accel(&input, &mut w.force, core.t_s, &core.x, &mut w.x_new);
        forces::add_velocity_accel(&input, &w.force, &core.v, &mut w.x_new);
        w.x_new.iter().sum()
    }

    /// The constraint phase (a full pass and its re-check passes) on a copy of the current state,
    /// as after an accepted step, for benchmarks and profiling. Returns the largest correction, metres.
    pub fn enforce_constraints_once(&mut self, poses: &mut dyn PoseSource, h_s: f32) -> f32 {
        self.ensure_start(poses);
        let core = &self.core;
        let w = &mut self.work;
        w.x_new.clone_from(&core.x);
        w.v_new.clone_from(&core.v);
        constrain_candidate(core, w, CandidateTime::Start, h_s, 0.0)
            .outcome
            .max_correction_m
    }

    /// Number of candidate-list rebuilds of the constraint broadphase so far.
    pub fn broadphase_rebuilds(&self) -> u64 {
        self.work.broad.rebuilds
    }

    fn current_grid(&self) -> [Vec<f32>; 3] {
        let mut grid: [Vec<f32>; 3] = Default::default();
        self.current_grid_into(&mut grid);
        grid
    }

    /// The fixed rows in the world at the state's time, when known (`Core::rings_world`, which
    /// holds the step's start whenever that is placed).
    fn current_rings(&self) -> Option<&[Vec<f32>; 3]> {
        let rings = &self.core.rings_world;
        (rings[0].len() == 2 * self.core.around).then_some(rings)
    }

    /// [`Self::current_grid`] into `grid`'s storage.
    fn current_grid_into(&self, grid: &mut [Vec<f32>; 3]) {
        let neutral;
        let rings = if let Some(rings) = self.current_rings() {
            rings
        } else {
            // Fixed rows at the neutral posture.
            neutral = soa(self.core.neutral_rings().into_iter());
            &neutral
        };
        forces::assemble_grid(
            self.core.around,
            self.core.along,
            &self.core.x,
            rings,
            rings,
            0.0,
            grid,
        );
    }

    /// The triangle mesh of a whole grid (SoA, fixed rings included), with its normals; a
    /// non-finite position or normal is drawn as the origin or +Y.
    fn mesh_from_grid(&self, grid: &[Vec<f32>; 3], out: &mut SurfaceMesh) {
        let (m, n) = (self.core.around, self.core.along);
        let mut normals = Default::default();
        forces::grid_normals(m, n, grid, &mut normals);
        out.positions_m.clear();
        out.normals.clear();
        out.indices.clear();
        for k in 0..m * n {
            let p = Vec3::new(grid[0][k], grid[1][k], grid[2][k]);
            let nr = Vec3::new(normals[0][k], normals[1][k], normals[2][k]);
            out.positions_m
                .push(if p.is_finite() { p } else { Vec3::ZERO });
            out.normals.push(if nr.is_finite() { nr } else { Vec3::Y });
        }
        for j in 0..n - 1 {
            for i in 0..m {
                let ip = (i + 1) % m;
                let p00 = (j * m + i) as u32;
                let p10 = (j * m + ip) as u32;
                let p01 = ((j + 1) * m + i) as u32;
                let p11 = ((j + 1) * m + ip) as u32;
                out.indices
                    .extend_from_slice(&[p00, p01, p11, p00, p11, p10]);
            }
        }
    }

    /// Keeps the current state as the one the skin is drawn from before the step about to be
    /// committed (see `Work::drawn_before`).
    fn keep_drawn_before(&mut self) {
        let mut before = std::mem::take(&mut self.work.drawn_before);
        self.current_grid_into(&mut before);
        self.work.drawn_before = before;
        self.work.drawn_before_t_s = Some(self.core.t_s);
    }

    /// Forgets the state before the last step (the current one no longer follows from it).
    fn forget_drawn_before(&mut self) {
        self.work.drawn_before_t_s = None;
    }

    /// Skeleton-driven kinematics at time `t_s` into the "end" slots of the work area.
    fn kinematics_end(&mut self, t_s: f64, poses: &mut dyn PoseSource) {
        let w = &mut self.work;
        kinematics_into(
            &self.core,
            t_s,
            poses,
            &mut w.posture,
            &mut w.pose,
            &mut w.shapes_end,
            &mut w.kin.rings_end,
            &mut w.kin.anchors_end,
            &mut w.anchor_scratch,
        );
    }

    fn ensure_start(&mut self, poses: &mut dyn PoseSource) {
        if self.work.start_valid {
            return;
        }
        let w = &mut self.work;
        kinematics_into(
            &self.core,
            self.core.t_s,
            poses,
            &mut w.posture,
            &mut w.pose,
            &mut w.shapes_start,
            &mut w.kin.rings_start,
            &mut w.kin.anchors_start,
            &mut w.anchor_scratch,
        );
        start_placed(&mut self.core, w);
    }

    /// Copies the state, when it is finite, into the checkpoint the guard goes back to. Every
    /// change of the state from outside a step saves one (construction,
    /// [`DeformationModel::apply`], `restore`, `set_resolution`) and so does the end of each
    /// `advance`, so between calls the checkpoint is always the state and `advance` need not
    /// save one at its start. (It did: with `leman simulate`'s slices of 1/30 s that copy
    /// repeated the one at the end of the slice before, about 85 kB of contacts on a 32×32 skin
    /// and 2 % of the torso's wall-clock profile.)
    fn save_checkpoint(&mut self) {
        if self.state_is_finite() {
            self.copy_checkpoint();
        }
    }

    /// Saves the state as the checkpoint without looking at it.
    fn copy_checkpoint(&mut self) {
        self.work.checkpoint_x.clone_from(&self.core.x);
        self.work.checkpoint_v.clone_from(&self.core.v);
        self.work.checkpoint_t_s = self.core.t_s;
        self.work.checkpoint_step_s = self.core.step_s;
        // An array's `clone_from` reuses each vector's storage.
        self.work
            .checkpoint_rings
            .clone_from(&self.core.rings_world);
        self.work
            .checkpoint_contacts
            .clone_from(&self.core.contacts);
    }

    /// [`DeformationModel::apply`] without the checkpoint that follows it.
    fn apply_change(&mut self, change: &ParameterChange) -> Result<(), SimError> {
        let core = &mut self.core;
        let free = core.free();
        let total = core.around * core.along;
        match change {
            ParameterChange::Stretch(sel, eta) => {
                for v in eta {
                    check_value("stretch", *v, false)?;
                }
                for k in selected(sel, total, "skin point")? {
                    for c in 0..3 {
                        core.materials.eta[c][k] = eta[c];
                    }
                }
            }
            ParameterChange::Bending(sel, xi) => {
                for v in xi {
                    check_value("bending", *v, false)?;
                }
                for k in selected(sel, total, "skin point")? {
                    for c in 0..3 {
                        core.materials.xi[c][k] = xi[c];
                    }
                }
                core.materials.has_bending =
                    core.materials.xi.iter().any(|a| a.iter().any(|v| *v > 0.0));
            }
            ParameterChange::RestMetricScale(sel, s) => {
                check_value("rest metric scale", *s, true)?;
                for k in selected(sel, total, "skin point")? {
                    for c in 0..3 {
                        core.materials.rest_metric[c][k] *= s;
                    }
                }
            }
            ParameterChange::Mass(sel, kg) => {
                check_value("mass", *kg, true)?;
                let mat = &mut core.materials;
                for f in selected_free(sel, core.around, free)? {
                    mat.mass_kg[f] = *kg;
                    mat.inv_mass[f] = 1.0 / kg;
                    mat.damping_per_mass[f] = mat.damping[f] / kg;
                }
            }
            ParameterChange::Damping(sel, d) => {
                check_value("damping", *d, false)?;
                let mat = &mut core.materials;
                for f in selected_free(sel, core.around, free)? {
                    mat.damping[f] = *d;
                    mat.damping_per_mass[f] = d / mat.mass_kg[f];
                }
            }
            ParameterChange::Fat(sel, fat) => {
                check_value("fat", *fat, false)?;
                for f in selected_free(sel, core.around, free)? {
                    core.materials.fat_m[f] = *fat;
                }
                self.work.broad.invalidate();
            }
            ParameterChange::TissueStiffness(sel, ks) => {
                check_value("tissue stiffness", *ks, false)?;
                let springs = selected_springs(sel, core.character.tissue.len(), &core.springs)?;
                for q in springs {
                    core.springs.ks[q] = *ks;
                }
            }
            ParameterChange::TissueDamping(sel, kd) => {
                check_value("tissue damping", *kd, false)?;
                let springs = selected_springs(sel, core.character.tissue.len(), &core.springs)?;
                for q in springs {
                    core.springs.kd[q] = *kd;
                }
            }
            ParameterChange::Gravity(g) => {
                if !g.is_finite() {
                    return Err(SimError::BadParameter(format!("gravity {g} is not finite")));
                }
                core.materials.gravity = *g;
            }
            ParameterChange::Contact {
                k_parallel,
                k_perpendicular,
            } => {
                for (name, k) in [
                    ("k_parallel", k_parallel),
                    ("k_perpendicular", k_perpendicular),
                ] {
                    if !crate::character::is_velocity_fraction(*k) {
                        return Err(SimError::BadParameter(format!(
                            "{name} {k} is not in [0, 1]"
                        )));
                    }
                }
                core.k_parallel = *k_parallel;
                core.k_perpendicular = *k_perpendicular;
            }
            ParameterChange::ConstraintTolerance(eps) => {
                check_value("epsilon_c", *eps, true)?;
                core.epsilon_c_m = *eps;
            }
            ParameterChange::RecheckFraction(f) => {
                if !crate::character::is_recheck_fraction(*f) {
                    return Err(SimError::BadParameter(format!(
                        "recheck_fraction {f} is not in (0, 1]"
                    )));
                }
                core.recheck_fraction = *f;
            }
            ParameterChange::HoldContacts(on) => {
                core.hold_contacts = *on;
                // Takes effect from the next step: the holds of the current state go (or are
                // made by the next pushes).
                if !on {
                    core.contacts.release_all();
                }
            }
            ParameterChange::Integrator(kind) => {
                core.kind = *kind;
                core.step_s = initial_step(*kind, &core.tolerances);
            }
            ParameterChange::Tolerances(t) => {
                t.check().map_err(SimError::BadParameter)?;
                core.tolerances = *t;
                core.step_s = initial_step(core.kind, t);
            }
        }
        Ok(())
    }

    /// Whether every position and velocity of the skin is finite.
    fn state_is_finite(&self) -> bool {
        // A fold without early exit, so the test vectorises (it runs every few steps).
        let finite = |a: &[f32]| a.iter().fold(true, |ok, x| ok & x.is_finite());
        finite(&self.core.x) & finite(&self.core.v)
    }

    fn restore_checkpoint(&mut self) {
        self.forget_drawn_before();
        if self.work.checkpoint_x.len() == self.core.x.len() {
            self.core.x.clone_from(&self.work.checkpoint_x);
            self.core.v.clone_from(&self.work.checkpoint_v);
            self.core.t_s = self.work.checkpoint_t_s;
            self.core.step_s = self.work.checkpoint_step_s;
            self.core
                .contacts
                .clone_from(&self.work.checkpoint_contacts);
            self.core
                .rings_world
                .clone_from(&self.work.checkpoint_rings);
        } else {
            // No checkpoint at this resolution: back to rest at the neutral posture.
            self.core.rings_world = Default::default();
            let rest = Core::rest_state(&self.core);
            self.core.x = rest;
            self.core.v.iter_mut().for_each(|v| *v = 0.0);
            self.core.step_s = self.core.tolerances.min_step_s;
            self.core.contacts.clear(self.core.free());
        }
        self.work.last_constraint_reject = None;
        self.work.start_valid = false;
        self.work.broad.invalidate();
    }

    /// One step attempt from the current state towards at most `h_s`. Returns what happened.
    fn attempt(
        &mut self,
        h_s: f64,
        poses: &mut dyn PoseSource,
        clock: Option<&dyn Clock>,
        report: &mut AdvanceReport,
    ) -> Attempt {
        let t0 = self.core.t_s;
        self.kinematics_end(t0 + h_s, poses);
        let core = &mut self.core;
        let w = &mut self.work;
        w.kin.t0_s = t0;
        w.kin.h_s = h_s;
        let integ = w
            .integrator
            .get_or_insert_with(|| Integrator::new(core.kind, core.tolerances));
        integ.set_kind(core.kind);
        integ.tolerances = core.tolerances;
        let n = core.x.len();
        w.x_new.resize(n, 0.0);
        w.v_new.resize(n, 0.0);
        let mut eval = Eval {
            input: ForceInput {
                around: core.around,
                along: core.along,
                materials: &core.materials,
                springs: &core.springs,
                kin: &w.kin,
            },
            scratch: &mut w.force,
            contacts: &core.contacts,
            clock,
            force_time: Duration::ZERO,
        };
        let p = integ.propose(
            &mut eval,
            t0,
            h_s,
            &core.x,
            &core.v,
            &mut w.x_new,
            &mut w.v_new,
        );
        report.phases.force += eval.force_time;
        report.force_evals += u64::from(p.position_evals);
        report.velocity_evals += u64::from(p.velocity_evals);
        let at_min = core.tolerances.at_min_step(h_s);
        if !p.accepted {
            // At the smallest step the integrator accepts any finite error, so a rejection
            // there means the error estimate itself is not finite (a state far outside the
            // model's range: a skin point a light-year away overflows the scaled error). A
            // fixed-step method rejects only on a bug. Retrying either would repeat the same
            // attempt forever; the guard counts it and gives up after `GUARD_ATTEMPTS`.
            if at_min || !core.kind.is_adaptive() {
                return Attempt::NonFinite;
            }
            return Attempt::ErrorRejected {
                next_s: p.next_step_s,
            };
        }
        // Guard: finite and no energy explosion (one vectorized pass over the candidate).
        let guard = forces::guard_scan(&core.materials, &w.x_new, &w.v_new, &core.v);
        if !guard.finite {
            return Attempt::NonFinite;
        }
        let max_speed2 = guard.max_speed2;
        let (ke_new, ke_old) = (guard.kinetic_energy_new_j, guard.kinetic_energy_old_j);
        let limit =
            10.0 * ke_old + 0.5 * guard.total_mass_kg * GUARD_SPEED_M_PER_S * GUARD_SPEED_M_PER_S;
        if ke_new.is_nan() || ke_new > limit {
            return Attempt::NonFinite;
        }
        // Constraints on the candidate.
        let c_start = clock.map(|c| c.now());
        let phase = constrain_candidate(core, w, CandidateTime::End, h_s as f32, max_speed2.sqrt());
        if let (Some(start), Some(c)) = (c_start, clock) {
            report.phases.constraints += c.now().saturating_sub(start);
        }
        report.constraint_phases += 1;
        report.recheck_passes += u64::from(phase.recheck_passes);
        report.rechecked_points += u64::from(phase.rechecked_points);
        report.unsettled_phases += u64::from(phase.unsettled);
        let outcome = phase.outcome;
        // Root bracketing assumes the correction shrinks with the step. When a retry at half
        // the step or less still needs ≥ 70 % of the previous correction, the penetration does
        // not come from this step's motion (e.g. a neighbour's correction turned the normal
        // that offsets the fat point): shrinking further cannot help, so accept (forced).
        let not_step_driven = match w.last_constraint_reject {
            Some((t_prev, h_prev, c_prev)) => {
                t_prev == t0 && h_s < h_prev && outcome.max_component_m >= 0.7 * c_prev
            }
            None => false,
        };
        if outcome.max_component_m > core.epsilon_c_m && !at_min && !not_step_driven {
            w.last_constraint_reject = Some((t0, h_s, outcome.max_component_m));
            // False position on [0, h]: the correction is about proportional to h.
            let ratio = f64::from(core.epsilon_c_m / outcome.max_component_m);
            let h_c = (h_s * 0.8 * ratio)
                .min(0.5 * h_s)
                .max(core.tolerances.min_step_s);
            return Attempt::ConstraintRejected { retry_s: h_c };
        }
        w.last_constraint_reject = None;
        Attempt::Accepted {
            next_s: p.next_step_s,
            forced: p.forced || outcome.max_component_m > core.epsilon_c_m,
            correction_m: outcome.max_correction_m,
            pushed: w.contact_mask.iter().map(|&b| u32::from(b)).sum(),
        }
    }

    fn commit(&mut self, h_s: f64) {
        let core = &mut self.core;
        let w = &mut self.work;
        std::mem::swap(&mut core.x, &mut w.x_new);
        std::mem::swap(&mut core.v, &mut w.v_new);
        core.t_s += h_s;
        std::mem::swap(&mut w.shapes_start, &mut w.shapes_end);
        std::mem::swap(&mut w.kin.rings_start, &mut w.kin.rings_end);
        std::mem::swap(&mut w.kin.anchors_start, &mut w.kin.anchors_end);
        std::mem::swap(&mut core.contacts, &mut w.candidate_contacts);
        start_placed(core, w);
    }
}

/// Marks the step's start in `w` (shapes, fixed rows, anchors) as placed by the skeleton at the
/// state's time, and keeps its fixed rows with the state: they are what the skin is drawn with
/// from now on, so a snapshot must hold them (else a restore after a call that took no step
/// would draw the ends with the resampled or the neutral rows instead).
fn start_placed(core: &mut Core, w: &mut Work) {
    core.rings_world.clone_from(&w.kin.rings_start);
    w.start_valid = true;
}

enum Attempt {
    ErrorRejected {
        next_s: f64,
    },
    ConstraintRejected {
        retry_s: f64,
    },
    NonFinite,
    Accepted {
        next_s: f64,
        forced: bool,
        correction_m: f32,
        /// Distinct skin points the constraint phase moved.
        pushed: u32,
    },
}

#[allow(clippy::too_many_arguments)]
fn kinematics_into(
    core: &Core,
    t_s: f64,
    poses: &mut dyn PoseSource,
    posture: &mut Posture,
    pose: &mut SkeletonPose,
    shapes: &mut Vec<ShapeInstance>,
    rings: &mut [Vec<f32>; 3],
    anchors: &mut [Vec<f32>; 3],
    anchor_scratch: &mut [Vec<f32>; 3],
) {
    let ch = &core.character;
    poses.posture_at(t_s, posture);
    ch.skeleton.forward_kinematics_into(posture, pose);
    ch.shape_instances_into(posture, pose, t_s as f32, shapes);
    let m = core.around;
    for r in rings.iter_mut() {
        r.resize(2 * m, 0.0);
    }
    let bottom = pose.world_from(ch.skin.bottom_joint);
    let top = pose.world_from(ch.skin.top_joint);
    for i in 0..m {
        let b = bottom.transform_point(core.bottom_ring_m[i]);
        let t = top.transform_point(core.top_ring_m[i]);
        for (c, (bv, tv)) in [(b.x, t.x), (b.y, t.y), (b.z, t.z)].into_iter().enumerate() {
            rings[c][i] = bv;
            rings[c][m + i] = tv;
        }
    }
    core.anchor_table.place(shapes, anchors, anchor_scratch);
}

impl Core {
    fn free(&self) -> usize {
        self.around * (self.along - 2)
    }

    fn from_character(character: Arc<Character>, kind: IntegratorKind) -> Result<Self, SimError> {
        let skin = &character.skin;
        let (m, n) = (skin.around as usize, skin.along as usize);
        if m < 3 || n < 3 {
            return Err(SimError::BadCharacter(format!(
                "skin resolution {m}×{n} is below 3×3"
            )));
        }
        let total = m * n;
        let free = m * (n - 2);
        let mut x = vec![0.0f32; 3 * free];
        for f in 0..free {
            let p = skin.positions_m[m + f];
            x[f] = p.x;
            x[free + f] = p.y;
            x[2 * free + f] = p.z;
        }
        let sym = |v: &[[f32; 3]]| -> [Vec<f32>; 3] {
            [
                v.iter().map(|t| t[0]).collect(),
                v.iter().map(|t| t[1]).collect(),
                v.iter().map(|t| t[2]).collect(),
            ]
        };
        let mass: Vec<f32> = skin.mass_kg[m..m + free].to_vec();
        let damping: Vec<f32> = skin.damping_n_s_per_m[m..m + free].to_vec();
        let xi = sym(&skin.bending);
        let has_bending = xi.iter().any(|a| a.iter().any(|v| *v > 0.0));
        let mut materials = Materials {
            eta: sym(&skin.stretch),
            rest_metric: sym(&skin.rest_metric),
            xi,
            rest_curvature: [vec![0.0; total], vec![0.0; total], vec![0.0; total]],
            has_bending,
            inv_mass: mass.iter().map(|m| 1.0 / m).collect(),
            damping_per_mass: damping.iter().zip(&mass).map(|(d, m)| d / m).collect(),
            mass_kg: mass,
            damping,
            fat_m: skin.fat_m[m..m + free].to_vec(),
            gravity: character.simulation.gravity_m_per_s2,
        };
        let grid = soa(skin.positions_m.iter().copied());
        materials.rest_curvature = rest_curvature(m, n, &grid);
        let mut springs = Springs::default();
        for (k, t) in character.tissue.iter().enumerate() {
            let idx = t.skin_point as usize;
            if idx < m || idx >= m + free {
                continue; // on a fixed row: no effect
            }
            springs.point.push((idx - m) as u32);
            springs.source.push(k as u32);
            springs.ks.push(t.stiffness_n_per_m);
            springs.kd.push(t.damping_n_s_per_m);
            springs.rest_m.push(t.rest_length_m);
            springs.shape.push(t.shape.0);
            springs.anchor_rest_m.push(t.anchor_rest_m);
        }
        let d = character.simulation;
        let tolerances = tolerances_of(&d);
        let step_s = initial_step(kind, &tolerances);
        Ok(Self {
            around: m,
            along: n,
            bottom_ring_m: skin.bottom_ring_m.clone(),
            top_ring_m: skin.top_ring_m.clone(),
            t_s: 0.0,
            step_s,
            v: vec![0.0; x.len()],
            x,
            materials,
            anchor_table: AnchorTable::new(&springs, character.shapes.len()),
            springs,
            kind,
            tolerances,
            k_parallel: d.k_parallel,
            k_perpendicular: d.k_perpendicular,
            epsilon_c_m: d.epsilon_c_m,
            recheck_fraction: d.recheck_fraction,
            contacts: ContactState::default(),
            hold_contacts: d.hold_contacts,
            rings_world: Default::default(),
            character,
        })
    }

    fn neutral_rings(&self) -> Vec<Vec3> {
        let ch = &self.character;
        let pose = ch
            .skeleton
            .forward_kinematics(&Posture::neutral(&ch.skeleton));
        let b = pose.world_from(ch.skin.bottom_joint);
        let t = pose.world_from(ch.skin.top_joint);
        let mut out: Vec<Vec3> = self
            .bottom_ring_m
            .iter()
            .map(|p| b.transform_point(*p))
            .collect();
        out.extend(self.top_ring_m.iter().map(|p| t.transform_point(*p)));
        out
    }

    /// The free points of the character's own rest shape, if the resolution matches; else the
    /// current state (used when a checkpoint is missing).
    fn rest_state(&self) -> Vec<f32> {
        let skin = &self.character.skin;
        if skin.around as usize == self.around && skin.along as usize == self.along {
            let free = self.free();
            let mut x = vec![0.0; 3 * free];
            for f in 0..free {
                let p = skin.positions_m[self.around + f];
                x[f] = p.x;
                x[free + f] = p.y;
                x[2 * free + f] = p.z;
            }
            x
        } else {
            self.x.clone()
        }
    }
}

/// The step control a character's `[simulation]` section asks for (steps in seconds; what the
/// file does not set keeps [`Tolerances::default`]). A file without `rk4_step_s` steps RK4 at
/// `euler_step_s`, as before the two were separate.
pub fn tolerances_of(d: &SimulationDefaults) -> Tolerances {
    Tolerances {
        euler_step_s: f64::from(d.euler_step_s),
        rk4_step_s: f64::from(d.rk4_step_or_euler_s()),
        min_step_s: f64::from(d.min_step_s),
        max_step_s: f64::from(d.max_step_s),
        position_tolerance: f64::from(d.epsilon_r),
        velocity_tolerance: f64::from(d.epsilon_v),
        position_threshold_m: f64::from(d.r_threshold_m),
        velocity_threshold_m_per_s: f64::from(d.v_threshold_m_per_s),
        ..Tolerances::default()
    }
}

/// First step: the fixed step for Euler and RK4; for the adaptive methods a quarter of the
/// largest step (the controller corrects it within a step or two; starting from the Euler step
/// would only report that as the smallest step).
fn initial_step(kind: IntegratorKind, t: &Tolerances) -> f64 {
    if kind.is_adaptive() {
        (0.25 * t.max_step_s).clamp(t.min_step_s, t.max_step_s.max(t.min_step_s))
    } else {
        Integrator::new(kind, *t).initial_step_s()
    }
}

/// Rest curvature `B⁰_ij = n̂·D_ij r` of a full grid (0 on the fixed rows).
fn rest_curvature(m: usize, n: usize, grid: &[Vec<f32>; 3]) -> [Vec<f32>; 3] {
    let mut normals = Default::default();
    forces::grid_normals(m, n, grid, &mut normals);
    let total = m * n;
    let mut out = [vec![0.0; total], vec![0.0; total], vec![0.0; total]];
    let at = |k: usize| Vec3::new(grid[0][k], grid[1][k], grid[2][k]);
    let idx = |i: usize, j: usize| j * m + (i % m);
    let (inv_h1, inv_h2) = (m as f32, (n - 1) as f32);
    for j in 1..n - 1 {
        for i in 0..m {
            let k = j * m + i;
            let nk = Vec3::new(normals[0][k], normals[1][k], normals[2][k]);
            let p = at(k);
            let d11 = (at(idx(i + 1, j)) - 2.0 * p + at(idx(i + m - 1, j))) * (inv_h1 * inv_h1);
            let d22 = (at(idx(i, j + 1)) - 2.0 * p + at(idx(i, j - 1))) * (inv_h2 * inv_h2);
            let d12 = (at(idx(i + 1, j + 1)) - at(idx(i + 1, j)) - at(idx(i, j + 1)) + p)
                * (inv_h1 * inv_h2);
            out[0][k] = nk.dot(d11);
            out[1][k] = nk.dot(d12);
            out[2][k] = nk.dot(d22);
        }
    }
    out
}

fn check_value(what: &str, v: f32, strictly_positive: bool) -> Result<(), SimError> {
    let ok = v.is_finite() && if strictly_positive { v > 0.0 } else { v >= 0.0 };
    if ok {
        Ok(())
    } else {
        Err(SimError::BadParameter(format!(
            "{what} must be finite and {} 0, got {v}",
            if strictly_positive { ">" } else { ">=" }
        )))
    }
}

/// The free points (indices into the per-free-point arrays) among the skin points `sel`
/// selects on a grid of `free` free points after the `around` points of the fixed first row;
/// the fixed rows' points are left out.
fn selected_free(sel: &Selection, around: usize, free: usize) -> Result<Vec<usize>, SimError> {
    let total = free + 2 * around;
    let points = selected(sel, total, "skin point")?;
    Ok(points
        .into_iter()
        .filter_map(|k| k.checked_sub(around).filter(|&f| f < free))
        .collect())
}

/// The model's springs (indices into [`forces::Springs`]) made from the character's tissue
/// springs `sel` selects out of `tissue_count`, by a mark per tissue spring (a search of the
/// selection per spring took `O(springs × selected)`: about 8 M comparisons for
/// `Selection::All` on the 128×128 torso's 16 128 springs).
fn selected_springs(
    sel: &Selection,
    tissue_count: usize,
    springs: &forces::Springs,
) -> Result<Vec<usize>, SimError> {
    let mut chosen = vec![false; tissue_count];
    for i in selected(sel, tissue_count, "tissue spring")? {
        chosen[i] = true;
    }
    Ok(springs
        .source
        .iter()
        .enumerate()
        .filter(|(_, src)| chosen.get(**src as usize).copied().unwrap_or(false))
        .map(|(q, _)| q)
        .collect())
}

fn selected(sel: &Selection, len: usize, what: &str) -> Result<Vec<usize>, SimError> {
    match sel {
        Selection::All => Ok((0..len).collect()),
        Selection::Some(ids) => ids
            .iter()
            .map(|&i| {
                let i = i as usize;
                if i < len {
                    Ok(i)
                } else {
                    Err(SimError::BadParameter(format!(
                        "{what} index {i} is out of range (0..{len})"
                    )))
                }
            })
            .collect(),
    }
}

impl DeformationModel for SurfaceModel {
    fn model_name(&self) -> &'static str {
        MODEL_NAME
    }

    fn time_s(&self) -> f64 {
        self.core.t_s
    }

    fn advance(
        &mut self,
        target_time_s: f64,
        poses: &mut dyn PoseSource,
        budget: &mut dyn StepBudget,
        clock: Option<&dyn Clock>,
    ) -> AdvanceReport {
        self.advance_past(target_time_s, target_time_s, poses, budget, clock)
    }

    fn advance_past(
        &mut self,
        target_time_s: f64,
        end_time_s: f64,
        poses: &mut dyn PoseSource,
        budget: &mut dyn StepBudget,
        clock: Option<&dyn Clock>,
    ) -> AdvanceReport {
        let begin = clock.map(|c| c.now());
        // Steps are shortened only to land on the end; a target short of it is reached by the
        // first step that passes it. An end before the target (or NaN) is the target.
        let end_time_s = end_time_s.max(target_time_s);
        let mut report = AdvanceReport::default();
        if !self.state_is_finite() {
            report.nonfinite_events += 1;
            self.restore_checkpoint();
        }
        self.ensure_start(poses);
        let min_step = self.core.tolerances.step_floor_s(self.core.kind);
        let mut consecutive_failures = 0u32;
        // The planned step before the current run of failures (restored if the guard gives up).
        let mut step_before_failures = self.core.step_s;
        let mut stalled = false;
        while target_time_s.is_finite() && self.core.t_s < target_time_s - TIME_RESOLUTION_S {
            if !budget.may_step() {
                break;
            }
            let remaining = end_time_s - self.core.t_s;
            let planned = self.core.step_s.max(min_step);
            // Avoid a sliver at the end: split the rest evenly if it is just over one step.
            let h = if remaining <= planned {
                remaining
            } else if remaining < 1.5 * planned {
                0.5 * remaining
            } else {
                planned
            };
            match self.attempt(h, poses, clock, &mut report) {
                Attempt::Accepted {
                    next_s,
                    forced,
                    correction_m,
                    pushed,
                } => {
                    if self.core.t_s + h >= target_time_s - TIME_RESOLUTION_S {
                        // The step that ends the call: its start is what the skin is drawn
                        // from at times before its end.
                        self.keep_drawn_before();
                    }
                    self.commit(h);
                    consecutive_failures = 0;
                    report.steps += 1;
                    report.forced_steps += u64::from(forced);
                    report.min_step_s = report.min_step_s.min(h);
                    report.max_step_s = report.max_step_s.max(h);
                    report.max_penetration_m = report.max_penetration_m.max(correction_m);
                    report.pushed_points += u64::from(pushed);
                    report.held_points += self.core.contacts.held_points() as u64;
                    // A step shortened to land on the target does not shrink the next one.
                    self.core.step_s = if h < planned {
                        planned.max(next_s)
                    } else {
                        next_s
                    };
                }
                Attempt::ErrorRejected { next_s } => {
                    report.rejected_steps += 1;
                    // The controller's own retry step (eq. 12 with the safety factor; at
                    // least a `safety` shrink, so a retry always makes progress). Halving
                    // regardless threw away half the step on errors just over ε_r.
                    let safety = self.core.tolerances.safety.clamp(0.1, 0.9);
                    self.core.step_s = next_s.min(safety * h).max(min_step);
                    if !self.core.kind.is_adaptive() {
                        // A fixed-step method only "rejects" on a bug; do not loop.
                        self.core.step_s = self.core.tolerances.fixed_step_s(self.core.kind);
                    }
                }
                Attempt::ConstraintRejected { retry_s } => {
                    report.rejected_steps += 1;
                    report.constraint_rejections += 1;
                    self.core.step_s = retry_s;
                }
                Attempt::NonFinite => {
                    report.rejected_steps += 1;
                    report.nonfinite_events += 1;
                    if consecutive_failures == 0 {
                        step_before_failures = self.core.step_s;
                    }
                    consecutive_failures += 1;
                    self.core.step_s = (0.25 * h).max(min_step);
                    if consecutive_failures >= GUARD_ATTEMPTS {
                        // Even tiny steps blow up from here: stop for this call (the report
                        // says `Stalled`). A failed attempt changes nothing, so the state is
                        // still the last accepted one, which passed the guard: it stays, with
                        // the step it had, and the steps accepted before it in this call are
                        // kept (going back to the call's start would throw them away and redo
                        // them, to the same stall, at the next call).
                        self.core.step_s = step_before_failures;
                        stalled = true;
                        break;
                    }
                }
            }
        }
        // Fixed-step methods return to their fixed step after a constraint-limited step.
        if !self.core.kind.is_adaptive() {
            self.core.step_s = self.core.tolerances.fixed_step_s(self.core.kind);
        }
        // The guard scans each step before its constraint phase; the projection and eq. 13 run
        // after it. A state they left non-finite (no valid parameters are known to do so since
        // k∥ and k⊥ are kept in [0, 1]) must not outlive the call, where positions, snapshots
        // and the checkpoint would carry it: back to the call's start, and say it stalled (the
        // next call would repeat the same steps).
        if self.state_is_finite() {
            self.copy_checkpoint();
        } else {
            report.nonfinite_events += 1;
            self.restore_checkpoint();
            stalled = true;
        }
        report.time_s = self.core.t_s;
        report.end = if self.core.t_s >= target_time_s - TIME_RESOLUTION_S {
            AdvanceEnd::ReachedTarget
        } else if stalled {
            AdvanceEnd::Stalled
        } else {
            AdvanceEnd::BudgetSpent
        };
        if let (Some(b), Some(c)) = (begin, clock) {
            let total = c.now().saturating_sub(b);
            report.phases.other = total
                .saturating_sub(report.phases.force)
                .saturating_sub(report.phases.constraints);
        }
        report
    }

    fn surface_mesh_into(&self, out: &mut SurfaceMesh) {
        self.mesh_from_grid(&self.current_grid(), out);
    }

    fn surface_mesh_at_into(&self, time_s: f64, out: &mut SurfaceMesh) {
        let mut grid = self.current_grid();
        let t1 = self.core.t_s;
        let before = &self.work.drawn_before;
        let same_grid = before.iter().zip(&grid).all(|(a, b)| a.len() == b.len());
        if let Some(t0) = self.work.drawn_before_t_s
            && t0 < t1
            && time_s < t1
            && same_grid
        {
            // Clamped to the two states: never drawn before the step's start.
            let w = ((time_s - t0) / (t1 - t0)).max(0.0) as f32;
            for (now, then) in grid.iter_mut().zip(before) {
                for (p, &q) in now.iter_mut().zip(then) {
                    *p = q + w * (*p - q);
                }
            }
        }
        self.mesh_from_grid(&grid, out);
    }

    fn apply(&mut self, change: &ParameterChange) -> Result<(), SimError> {
        let applied = self.apply_change(change);
        // Some changes touch the state (a new integrator's step, holds released); a refused
        // one changed nothing.
        self.save_checkpoint();
        applied
    }

    fn snapshot(&self) -> Snapshot {
        Snapshot::new(MODEL_NAME, self.core.t_s, self.core.clone())
    }

    fn restore(&mut self, snapshot: &Snapshot) -> Result<(), SimError> {
        if snapshot.model != MODEL_NAME {
            return Err(SimError::BadSnapshot(format!(
                "made by the {} model, not the {MODEL_NAME} model",
                snapshot.model
            )));
        }
        let Some(core) = snapshot.data::<Core>() else {
            return Err(SimError::BadSnapshot("unreadable surface state".into()));
        };
        if !Arc::ptr_eq(&core.character, &self.core.character)
            && *core.character != *self.core.character
        {
            return Err(SimError::BadSnapshot(
                "made from a different character".into(),
            ));
        }
        if !(core.x.iter().all(|v| v.is_finite()) && core.v.iter().all(|v| v.is_finite())) {
            return Err(SimError::BadSnapshot("holds non-finite values".into()));
        }
        self.core = core.clone();
        self.forget_drawn_before();
        self.work.start_valid = false;
        self.work.last_constraint_reject = None;
        self.work.broad.invalidate();
        self.work.checkpoint_x.clear();
        self.save_checkpoint();
        Ok(())
    }

    fn resolution(&self) -> (u32, u32) {
        (self.core.around as u32, self.core.along as u32)
    }

    fn set_resolution(&mut self, around: u32, along: u32) -> Result<(), SimError> {
        if !(3..=1024).contains(&around) || !(3..=1024).contains(&along) {
            return Err(SimError::BadResolution {
                around,
                along,
                reason: "each side must be between 3 and 1024".into(),
            });
        }
        let current_rings = self.current_rings().cloned();
        self.core = resample::resample(&self.core, around as usize, along as usize, current_rings);
        // The contacts name points of the old grid.
        let free = self.core.free();
        self.core.contacts.clear(free);
        self.forget_drawn_before();
        self.work.start_valid = false;
        self.work.broad.invalidate();
        self.work.checkpoint_x.clear();
        self.save_checkpoint();
        Ok(())
    }

    fn point_count(&self) -> usize {
        self.core.around * self.core.along
    }
}

/// Which end of the step the candidate state belongs to (the skeleton's fixed rings and shapes
/// used for the constraint phase).
#[derive(Debug, Clone, Copy)]
enum CandidateTime {
    /// The committed state (benchmarks): shapes and rings at the step's start.
    Start,
    /// A proposed step: shapes and rings at its end.
    End,
}

/// What a constraint phase found and how much re-checking it did.
#[derive(Debug, Clone, Copy, Default)]
struct PhaseOutcome {
    /// The corrections of all its passes.
    outcome: constraints::ConstraintOutcome,
    /// Re-check passes after the full pass (at most [`MAX_RECHECK_PASSES`]).
    recheck_passes: u32,
    /// Points those passes tested, summed.
    rechecked_points: u32,
    /// The passes stopped at [`MAX_RECHECK_PASSES`] while still correcting by more than the
    /// re-check threshold.
    unsettled: bool,
}

/// Re-check passes a constraint phase may make after its full pass. Each pass re-tests the
/// neighbourhoods of the last pass's large corrections with their turned normals; at a crease
/// the points and their neighbours' normals can take several passes to settle. Measured over
/// 10 s of each motion: with at most 3 passes, 3 % of the torso's phases and 9 % of the arm's
/// stopped still correcting, leaving fat points up to 2.7 mm (torso), 2.2 mm (arm) and 3.7 mm
/// (wombat) deep; with 8, 0.3 % and 0.6 % did, the deepest residuals sampled every 1/30 s fell
/// to 0.95 mm (torso) and 0.6 mm (wombat), the arm took 9 % fewer steps and 22 % fewer
/// constraint rejections, and wall time was the same within noise or faster (torso +1 %, arm
/// −5 %, wombat −6 %: the passes beyond the third hold a handful of points, and the deep
/// leftovers they remove cost the next step). With 20, every phase settled (the slowest in 17
/// passes): the iteration converges, slowly at a few creases, and this cap bounds it.
pub const MAX_RECHECK_PASSES: u32 = 8;

/// Attempts in a row that may be non-finite or exploding before [`SurfaceModel::advance`]
/// gives up for the call ([`AdvanceEnd::Stalled`]). Each retry is a quarter of the last step
/// and at least the minimum step: from a 16 ms step with the examples' 0.1 ms minimum, the
/// fifth to the eighth attempts are all at the minimum.
pub const GUARD_ATTEMPTS: u32 = 8;

/// What to look at when the simulation stalls (its guard gave up, [`AdvanceEnd::Stalled`])
/// with integrator `kind`: one clause, for the end of a message. Out-of-range forces stall any
/// method; a fixed step too long for the skin also stalls a fixed-step method, slowly, after a
/// good start (explicit Euler gains energy in every lightly damped mode).
pub fn stall_advice(kind: IntegratorKind) -> String {
    match kind.fixed_step_field() {
        Some(field) => format!(
            "{STALL_FORCES_ADVICE}; with {} (fixed step), also a step too long for the skin: \
             try a smaller {field} in the character's [simulation] or an adaptive integrator",
            kind.name()
        ),
        None => STALL_FORCES_ADVICE.to_string(),
    }
}

/// The part of [`stall_advice`] that holds for every method (front ends that name their own
/// controls for the step use it alone).
pub const STALL_FORCES_ADVICE: &str = "the character's forces are out of range: look for a huge \
                                       stiffness, a tiny mass, or a shape or tissue anchor far \
                                       from the skin";

/// The constraint phase on the candidate in `w.x_new`/`w.v_new`: one full pass, then re-check
/// passes over corrected neighbourhoods with refreshed normals until nothing moves (at most
/// [`MAX_RECHECK_PASSES`]). Shared by the real step and the benchmark hook so both measure the
/// same work.
fn constrain_candidate(
    core: &Core,
    w: &mut Work,
    when: CandidateTime,
    h_s: f32,
    max_speed_m_per_s: f32,
) -> PhaseOutcome {
    let free = core.free();
    let (rings, shapes_end) = match when {
        CandidateTime::Start => (&w.kin.rings_start, &w.shapes_start),
        CandidateTime::End => (&w.kin.rings_end, &w.shapes_end),
    };
    forces::assemble_grid(
        core.around,
        core.along,
        &w.x_new,
        rings,
        rings,
        0.0,
        &mut w.force.grid,
    );
    fat_normals(core, &w.force.grid, &mut w.normals);
    w.x_unconstrained.clone_from(&w.x_new);
    let max_fat = core.materials.fat_m.iter().fold(0.0f32, |a, b| a.max(*b));
    let input = ConstraintInput {
        around: core.around,
        along: core.along,
        shapes_end,
        shapes_start: &w.shapes_start,
        h_s,
        fat_m: &core.materials.fat_m,
        max_fat_m: max_fat,
        k_parallel: core.k_parallel,
        k_perpendicular: core.k_perpendicular,
        max_speed_m_per_s,
        recheck_m: core.recheck_fraction * core.epsilon_c_m,
        rounds: constraints::MAX_ROUNDS,
    };
    // The first pass makes one round over the shapes. A point that a later shape pushed into an
    // earlier, overlapping one was outside that one before the push, so it is at most as deep
    // as the push was long: pushes over `recheck_m` put it in `touched`, and the re-checks below
    // (every shape, every round) fix it; shorter ones leave it less than `recheck_m` deep. The
    // second and third rounds of the first pass moved about 14 points per simulated second on
    // the torso while re-testing every moved point: 7 % of the run's instructions.
    let first = ConstraintInput { rounds: 1, ..input };
    let mut outcome = constraints::enforce(
        &first,
        &mut w.broad,
        &mut w.force.grid,
        &w.normals,
        &mut w.x_new,
        &mut w.v_new,
        None,
        &mut w.touched,
    );
    w.contact_mask.clear();
    w.contact_mask.resize(free, 0);
    w.broad.mark_moved(&mut w.contact_mask);
    if !core.hold_contacts {
        // The projection alone also leaves the full pass's push direction to the error
        // estimate (see `ContactState::update`).
        w.first_mask.clone_from(&w.contact_mask);
        for (first, last) in w.first_normal.iter_mut().zip(w.broad.pushes().normal) {
            first.clone_from(last);
        }
    }
    let (mut passes, mut rechecked_points) = (0, 0);
    // Corrections no longer than the re-check threshold do not warrant another pass.
    let mut last_corrected = if outcome.max_correction_m > input.recheck_m {
        outcome.corrected
    } else {
        0
    };
    while last_corrected > 0 && passes < MAX_RECHECK_PASSES {
        // Corrections turn their neighbours' normals, which moves those neighbours' fat
        // points: further passes over the corrected points and their neighbours with the
        // new normals, until nothing moves.
        passes += 1;
        constraints::neighbourhood(core.around, free, &w.touched, &mut w.flags, &mut w.recheck);
        rechecked_points += w.recheck.len() as u32;
        // The pass reads the normals of the re-checked points only (their fat points, and the
        // moved ones' new positions), so only theirs are brought up to date.
        let nodes = w.recheck.iter().map(|&f| core.around + f as usize);
        forces::grid_normals_strided_at(
            core.around,
            core.along,
            fat_stride(core),
            &w.force.grid,
            nodes,
            &mut w.normals,
        );
        let second = constraints::enforce(
            &input,
            &mut w.broad,
            &mut w.force.grid,
            &w.normals,
            &mut w.x_new,
            &mut w.v_new,
            Some(&w.recheck),
            &mut w.touched,
        );
        w.broad.mark_moved(&mut w.contact_mask);
        last_corrected = if second.max_correction_m > input.recheck_m {
            second.corrected
        } else {
            0
        };
        outcome.max_component_m = outcome.max_component_m.max(second.max_component_m);
        if second.max_correction_m > outcome.max_correction_m {
            outcome.max_correction_m = second.max_correction_m;
            outcome.worst = second.worst;
        }
    }
    w.candidate_contacts.update(
        &core.contacts,
        &PhaseEnd {
            pushed: &w.contact_mask,
            pushes: w.broad.pushes(),
            shapes: shapes_end,
            first: (!core.hold_contacts).then_some((&w.first_mask, &w.first_normal)),
        },
        core.hold_contacts,
        &mut w.contact_scratch,
    );
    absorb_cancelled_velocity(
        free,
        h_s,
        &core.x,
        &w.x_unconstrained,
        &w.x_new,
        &mut w.v_new,
        &w.contact_mask,
    );
    PhaseOutcome {
        outcome,
        recheck_passes: passes,
        rechecked_points,
        unsettled: last_corrected > 0,
    }
}

/// A contact point's speed counts as out of proportion to its motion above this many times its
/// displacement over the step (plus [`SPEED_SLACK_M_PER_S`]).
const MOTION_FACTOR: f32 = 2.0;
/// Speed a contact point may have beyond [`MOTION_FACTOR`] × its displacement rate, m/s.
const SPEED_SLACK_M_PER_S: f32 = 0.05;

/// Eq. 13 per pass removes the velocity along the shape's normal where each projection ends.
/// A point can also be held back by corrections in other directions over the passes (its fat
/// point `r − τ n̂` moves when the skin normal turns, several shapes push it, re-checks push it
/// again); the velocity those cancelled stayed, and at creases it grew step after step while
/// the point did not move (found on the 16×16 torso: 7-9 m/s at a standing point, with 800
/// constraint rejections per simulated second). So after the phase, a moved point whose speed
/// is out of proportion to how far it actually went this step (`|v| h > 2 |Δr| + h · 0.05 m/s`)
/// loses the component of its velocity against its total correction
/// `D = r_constrained − r_unconstrained` (the motion the constraints cancelled). Points whose
/// velocity matches their motion (ordinary sliding and resting contact) are left to eq. 13
/// alone: removing that component at every contact point took 4-24 % more steps.
///
/// It runs as one vectorised pass over every free point with the non-contacts (`contact` byte
/// 0) masked out, since most free points are contacts, and treats each point once however many
/// passes moved it.
#[allow(clippy::too_many_arguments)] // each SoA slice is its own argument (see `sim::simd`)
fn absorb_cancelled_velocity(
    free: usize,
    h_s: f32,
    x0: &[f32],
    x_unconstrained: &[f32],
    x: &[f32],
    v: &mut [f32],
    contact: &[u8],
) {
    let ([s0, s1, s2], [u0, u1, u2], [x0, x1, x2]) = (
        forces::blocks(x0, free),
        forces::blocks(x_unconstrained, free),
        forces::blocks(x, free),
    );
    let [v0, v1, v2] = forces::blocks_mut(v, free);
    absorb_pass(h_s, s0, s1, s2, u0, u1, u2, x0, x1, x2, v0, v1, v2, contact);
}

crate::sim::simd::multiversion! {
    /// [`absorb_cancelled_velocity`]'s arithmetic for every point whose `contact` byte is set,
    /// with the operations (and their order) of the `glam` expressions it was written with:
    /// `d = (x − x_u).normalize_or_zero()`, `a = v · d`, `|x − x0|`, `|v|`, `v − d a`.
    #[allow(clippy::too_many_arguments)]
    fn absorb_pass(
        h_s: f32,
        // The step's start positions, the unconstrained and the constrained candidate, and
        // the candidate's velocities (SoA components).
        s0: &[f32],
        s1: &[f32],
        s2: &[f32],
        u0: &[f32],
        u1: &[f32],
        u2: &[f32],
        x0: &[f32],
        x1: &[f32],
        x2: &[f32],
        v0: &mut [f32],
        v1: &mut [f32],
        v2: &mut [f32],
        contact: &[u8],
    ) {
        let n = contact.len().min(s0.len()).min(s1.len()).min(s2.len());
        let n = n.min(u0.len()).min(u1.len()).min(u2.len());
        let n = n.min(x0.len()).min(x1.len()).min(x2.len());
        let n = n.min(v0.len()).min(v1.len()).min(v2.len());
        let slack = SPEED_SLACK_M_PER_S * h_s;
        for f in 0..n {
            let (cx, cy, cz) = (x0[f] - u0[f], x1[f] - u1[f], x2[f] - u2[f]);
            let rcp = 1.0 / ((cx * cx) + (cy * cy) + (cz * cz)).sqrt();
            let unit = rcp.is_finite() & (rcp > 0.0);
            let (dx, dy, dz) = if unit {
                (cx * rcp, cy * rcp, cz * rcp)
            } else {
                (0.0, 0.0, 0.0)
            };
            let (vx, vy, vz) = (v0[f], v1[f], v2[f]);
            let against = (vx * dx) + (vy * dy) + (vz * dz);
            let (mx, my, mz) = (x0[f] - s0[f], x1[f] - s1[f], x2[f] - s2[f]);
            let moved = ((mx * mx) + (my * my) + (mz * mz)).sqrt();
            let speed = ((vx * vx) + (vy * vy) + (vz * vz)).sqrt();
            let out_of_proportion = speed * h_s > MOTION_FACTOR * moved + slack;
            let absorb = (contact[f] != 0) & (against < 0.0) & out_of_proportion;
            v0[f] = if absorb { vx - dx * against } else { vx };
            v1[f] = if absorb { vy - dy * against } else { vy };
            v2[f] = if absorb { vz - dz * against } else { vz };
        }
    }
}

/// Node strides (around, along) of the normals that offset the fat points (eq. 6): the
/// character model's rule ([`crate::character::skin::fat_normal_stride`]), so the simulator's
/// fat points are the model's ([`crate::character::Skin::fat_normals`]).
fn fat_stride(core: &Core) -> (usize, usize) {
    crate::character::skin::fat_normal_stride(core.around, core.along)
}

/// The normals that offset the fat points of `grid` (the full grid of `core`'s skin).
fn fat_normals(core: &Core, grid: &[Vec<f32>; 3], out: &mut [Vec<f32>; 3]) {
    forces::grid_normals_strided(core.around, core.along, fat_stride(core), grid, out);
}
