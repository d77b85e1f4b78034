//! The workstation's state and its frame work: the character and its simulation, the motion
//! and time, the calibration and stereo settings, the device source, the navigation vehicle,
//! the layers shown; and [`AppFrame`], which does one frame's work for the
//! [`Scheduler`] in the order of the paper's time-line.
//!
//! Frames of reference: device poses arrive in the tracker frame and are carried into the
//! physical (screen) frame by the calibration (`world_from_tracker`; the desktop stand-ins are
//! already in it). The vehicle maps the physical frame into the character's world. The head
//! stays at the calibration's default viewing position while no head pose has arrived.

use crate::app::scene::{SceneInputs, ShapeMeshes, build_scene};
use crate::app::scheduler::{
    FrameRecord, FrameWork, Scheduler, SimProgress, TimedAxes, TimedPose, TrackerRead,
};
use crate::app::vehicle::Vehicle;
use crate::calibration::CalibrationProfile;
use crate::character::{Character, Posture, SkeletonPose};
use crate::clock::{Clock, VirtualClock};
use crate::devices::hub::{DeviceState, HubSnapshot};
use crate::devices::profile::Role;
use crate::devices::replay::DeviceSource;
use crate::pose::Pose;
use crate::render::scene::{Layers, Scene};
use crate::sim::{
    AdvanceEnd, AdvanceReport, DeformationModel, IntegratorKind, ParameterChange, PoseSource,
    Selection, SurfaceMesh, Tolerances,
};
use crate::stereo::{OutputSettings, StereoViews, ViewSettings, eye_views};
use crate::tracking::{PredictorConfig, RoleTracker};
use glam::Vec3;
use std::time::Duration;

/// Draws a scene with both eyes' views composed by the stereo settings (the GPU at the edge;
/// a fake in tests).
pub trait FrameRenderer {
    /// Renders presented frame `frame_index`.
    fn render(
        &mut self,
        scene: &Scene,
        views: &StereoViews,
        output: &OutputSettings,
        frame_index: u64,
    ) -> Result<(), String>;
}

/// The character's parameters as the panel edits them (applied to every point or spring).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CharacterParams {
    /// Multiplier on the skin's stretch and shear elasticity η (1 = as in the file).
    pub elasticity_scale: f32,
    /// Mass of each skin point, kg.
    pub point_mass_kg: f32,
    /// Damping of each skin point, N·s/m.
    pub point_damping_n_s_per_m: f32,
    /// Connective tissue spring stiffness, N/m.
    pub tissue_stiffness_n_per_m: f32,
    /// Connective tissue spring damping, N·s/m.
    pub tissue_damping_n_s_per_m: f32,
    /// Fat thickness, metres.
    pub fat_m: f32,
}

impl CharacterParams {
    /// The values a character starts with (means over its points and springs).
    pub fn of(character: &Character) -> Self {
        let mean = |v: &mut dyn Iterator<Item = f32>| {
            let (sum, n) = v.fold((0.0f64, 0usize), |(s, n), x| (s + f64::from(x), n + 1));
            if n == 0 { 0.0 } else { (sum / n as f64) as f32 }
        };
        Self {
            elasticity_scale: 1.0,
            point_mass_kg: mean(&mut character.skin.mass_kg.iter().copied()),
            point_damping_n_s_per_m: mean(&mut character.skin.damping_n_s_per_m.iter().copied()),
            tissue_stiffness_n_per_m: mean(
                &mut character.tissue.iter().map(|s| s.stiffness_n_per_m),
            ),
            tissue_damping_n_s_per_m: mean(
                &mut character.tissue.iter().map(|s| s.damping_n_s_per_m),
            ),
            fat_m: mean(&mut character.skin.fat_m.iter().copied()),
        }
    }

    /// The parameter changes that take a model from `self` to `next` (only what changed).
    pub fn changes_to(&self, next: &Self, character: &Character) -> Vec<ParameterChange> {
        let mut out = Vec::new();
        let differs = |a: f32, b: f32| (a - b).abs() > f32::EPSILON * a.abs().max(1.0);
        if differs(self.elasticity_scale, next.elasticity_scale) {
            let base = mean_sym2(&character.skin.stretch);
            let s = next.elasticity_scale;
            out.push(ParameterChange::Stretch(
                Selection::All,
                [base[0] * s, base[1] * s, base[2] * s],
            ));
        }
        if differs(self.point_mass_kg, next.point_mass_kg) {
            out.push(ParameterChange::Mass(Selection::All, next.point_mass_kg));
        }
        if differs(self.point_damping_n_s_per_m, next.point_damping_n_s_per_m) {
            out.push(ParameterChange::Damping(
                Selection::All,
                next.point_damping_n_s_per_m,
            ));
        }
        if differs(self.tissue_stiffness_n_per_m, next.tissue_stiffness_n_per_m) {
            out.push(ParameterChange::TissueStiffness(
                Selection::All,
                next.tissue_stiffness_n_per_m,
            ));
        }
        if differs(self.tissue_damping_n_s_per_m, next.tissue_damping_n_s_per_m) {
            out.push(ParameterChange::TissueDamping(
                Selection::All,
                next.tissue_damping_n_s_per_m,
            ));
        }
        if differs(self.fat_m, next.fat_m) {
            out.push(ParameterChange::Fat(Selection::All, next.fat_m));
        }
        out
    }
}

fn mean_sym2(v: &[[f32; 3]]) -> [f32; 3] {
    if v.is_empty() {
        return [0.0; 3];
    }
    let n = v.len() as f32;
    let s = v
        .iter()
        .fold([0.0f32; 3], |a, x| [a[0] + x[0], a[1] + x[1], a[2] + x[2]]);
    [s[0] / n, s[1] / n, s[2] / n]
}

/// The paper's Table 1 figures, measured live over the simulation since the last reset.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Table1 {
    /// All reports merged.
    pub totals: AdvanceReport,
    /// Simulated time covered, seconds.
    pub simulated_s: f64,
    /// Wall time spent simulating (scheduler's measure), seconds.
    pub wall_s: f64,
}

impl Table1 {
    /// Wall seconds per simulated second (the paper's "simulation slowdown").
    pub fn slowdown(&self) -> Option<f64> {
        (self.simulated_s > 0.0).then(|| self.wall_s / self.simulated_s)
    }
    /// Smallest and largest accepted step, milliseconds.
    pub fn step_interval_ms(&self) -> Option<(f64, f64)> {
        (self.totals.steps > 0)
            .then_some((self.totals.min_step_s * 1e3, self.totals.max_step_s * 1e3))
    }
    /// Percent of simulation time in force evaluation, constraints and other.
    pub fn percent(&self) -> (f64, f64, f64) {
        let (f, c, o) = self.totals.phases.fractions();
        (f * 100.0, c * 100.0, o * 100.0)
    }
}

/// How tracker reads get their time during a replay: the session clock is set by the frame,
/// so a replay gives the same samples on any machine.
#[derive(Debug, Clone)]
pub struct ReplayTiming {
    /// The clock the replayed device source reads.
    pub clock: VirtualClock,
    /// Session time of the current frame's start.
    pub frame_start: Duration,
    /// The frame period.
    pub period: Duration,
    /// Fraction of the frame at which the second read happens (just before rendering).
    pub second_read_fraction: f64,
}

/// The workstation's state.
pub struct AppState {
    /// The character shown and simulated.
    pub character: Character,
    shape_meshes: ShapeMeshes,
    /// Its deformation model (none when it could not be built; see `sim_error`).
    pub model: Option<Box<dyn DeformationModel + Send>>,
    /// Why there is no model, or the last refused parameter change.
    pub sim_error: Option<String>,
    /// Simulated time, seconds, at which the model's guard last gave up (every attempt down to
    /// the minimum step non-finite or exploding: the skin stands still there); cleared by the
    /// next accepted step.
    pub sim_stalled_at_s: Option<f64>,
    /// Why the last attempted render failed (for example a stereo output larger than the
    /// device's largest render target), shown in the stereo panel; cleared by the next frame
    /// that renders. Each new message is logged once, not every frame.
    pub render_failure: Option<String>,
    /// The skin is simulated while this is on.
    pub simulation_on: bool,
    /// The integrator in use.
    pub integrator: IntegratorKind,
    /// Step-size control settings in use.
    pub tolerances: Tolerances,
    /// Constraint tolerance ε_c in use, metres.
    pub epsilon_c_m: f32,
    /// Re-check threshold in use, as a fraction of ε_c.
    pub recheck_fraction: f32,
    /// Whether muscles hold the skin resting on them between steps.
    pub hold_contacts: bool,
    /// Index of the motion played (none: the neutral posture).
    pub motion: Option<usize>,
    /// Character parameters as last applied.
    pub params: CharacterParams,
    /// Parameter changes waiting for the next frame's update phase.
    pub pending_changes: Vec<ParameterChange>,
    /// The screen calibration.
    pub calibration: CalibrationProfile,
    /// Eye view settings (IPD override, clip planes, comfort).
    pub view_settings: ViewSettings,
    /// Stereo output mode.
    pub output: OutputSettings,
    /// Where device samples come from (live hub or replay).
    pub devices: Box<dyn DeviceSource>,
    /// The navigation vehicle.
    pub vehicle: Vehicle,
    /// Layers shown.
    pub layers: Layers,
    /// Skin opacity (1 = opaque).
    pub skin_opacity: f32,
    /// The frame scheduler.
    pub scheduler: Scheduler,
    /// The newest device snapshot (for the devices panel).
    pub last_snapshot: Option<HubSnapshot>,
    /// The newest frame record.
    pub last_record: Option<FrameRecord>,
    /// Live Table-1 figures.
    pub table1: Table1,
    /// The last good eye views.
    pub last_views: Option<StereoViews>,
    /// Replay timing, when replaying.
    pub replay_timing: Option<ReplayTiming>,
    posture: Posture,
    skeleton_pose: SkeletonPose,
    surface: SurfaceMesh,
    skin_grid: (u32, u32),
    last_update_at: Option<Duration>,
    reads_this_frame: u8,
    shown_time_s: f64,
    last_scene_wall: Duration,
    head_tracker: RoleTracker,
    wand_tracker: RoleTracker,
}

impl std::fmt::Debug for AppState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AppState")
            .field("character", &self.character.name)
            .field("simulation_on", &self.simulation_on)
            .field("frames", &self.scheduler.frames())
            .finish_non_exhaustive()
    }
}

/// A boxed deformation model with its first error, if the model could not be built.
pub type ModelResult = Result<Box<dyn DeformationModel + Send>, String>;

impl AppState {
    /// The state for `character`, simulated by `model` (or shown unsimulated with the error),
    /// calibrated by `calibration`, reading `devices`, scheduled by `scheduler`.
    pub fn new(
        character: Character,
        model: ModelResult,
        calibration: CalibrationProfile,
        devices: Box<dyn DeviceSource>,
        scheduler: Scheduler,
    ) -> Self {
        let shape_meshes = ShapeMeshes::new(&character);
        let posture = Posture::neutral(&character.skeleton);
        let skeleton_pose = character.skeleton.forward_kinematics(&posture);
        let (model, sim_error) = match model {
            Ok(m) => (Some(m), None),
            Err(e) => (None, Some(e)),
        };
        let vehicle = frame_character(&character, &skeleton_pose, &calibration);
        let params = CharacterParams::of(&character);
        let d = character.simulation;
        let tolerances = crate::sim::surface::tolerances_of(&d);
        let motion = (!character.motions.is_empty()).then_some(0);
        let (head_filter, wand_filter) = (calibration.head_filter, calibration.wand_filter);
        let mut scheduler = scheduler;
        if let Some(m) = &model {
            scheduler.assume_points(u32::try_from(m.point_count()).unwrap_or(u32::MAX));
        }
        let mut state = Self {
            shape_meshes,
            model,
            sim_error,
            sim_stalled_at_s: None,
            render_failure: None,
            simulation_on: true,
            integrator: IntegratorKind::Verlet,
            tolerances,
            epsilon_c_m: d.epsilon_c_m,
            recheck_fraction: d.recheck_fraction,
            hold_contacts: d.hold_contacts,
            motion,
            params,
            // What the panel shows is what the model uses.
            pending_changes: vec![ParameterChange::Tolerances(tolerances)],
            calibration,
            view_settings: ViewSettings::default(),
            output: OutputSettings::default(),
            devices,
            vehicle,
            layers: Layers::default(),
            skin_opacity: 1.0,
            scheduler,
            last_snapshot: None,
            last_record: None,
            table1: Table1::default(),
            last_views: None,
            replay_timing: None,
            posture,
            skeleton_pose,
            surface: SurfaceMesh::default(),
            skin_grid: (character.skin.around, character.skin.along),
            last_update_at: None,
            reads_this_frame: 0,
            shown_time_s: 0.0,
            last_scene_wall: Duration::ZERO,
            head_tracker: RoleTracker::new(head_filter, PredictorConfig::default()),
            wand_tracker: RoleTracker::new(wand_filter, PredictorConfig::default()),
            character,
        };
        state.refresh_surface();
        state
    }

    /// Queues a parameter change (applied between steps, at the next frame's update phase).
    pub fn queue_change(&mut self, change: ParameterChange) {
        self.pending_changes.push(change);
    }

    /// Sets the character parameters (queues the changes that differ).
    pub fn set_params(&mut self, next: CharacterParams) {
        let changes = self.params.changes_to(&next, &self.character);
        self.pending_changes.extend(changes);
        self.params = next;
    }

    /// Skin grid (around, along) shown.
    pub fn skin_grid(&self) -> (u32, u32) {
        self.skin_grid
    }

    /// The skin surface as last read from the model.
    pub fn surface(&self) -> &SurfaceMesh {
        &self.surface
    }

    /// The posture shown.
    pub fn posture(&self) -> &Posture {
        &self.posture
    }

    /// Runs one frame through the scheduler, rendering with `renderer`.
    pub fn run_frame(
        &mut self,
        clock: &dyn Clock,
        renderer: &mut dyn FrameRenderer,
    ) -> FrameRecord {
        // The scheduler drives `self` as its frame work; run a copy and put it back.
        let mut scheduler = self.scheduler.clone();
        let (record, rendered) = {
            let mut frame = AppFrame {
                state: self,
                renderer,
                clock,
                rendered: None,
            };
            let r = scheduler.run_frame(clock, &mut frame);
            (r, frame.rendered)
        };
        self.scheduler = scheduler;
        match rendered {
            Some(Err(e)) => {
                if self.render_failure.as_deref() != Some(e.as_str()) {
                    tracing::warn!("render failed: {e}");
                }
                self.render_failure = Some(e);
            }
            Some(Ok(())) => self.render_failure = None,
            None => {}
        }
        let mut record = record;
        record.scene_wall_s = self.last_scene_wall.as_secs_f64();
        self.table1.wall_s += record.sim_wall_s;
        if record.deforming {
            self.table1.simulated_s += record.sim_advanced_s;
        }
        self.last_record = Some(record.clone());
        record
    }

    /// The head pose (physical frame) to view from: the tracked head or the calibrated
    /// viewing position.
    pub fn head_physical(&self, read: &TrackerRead) -> Pose {
        read.head
            .map(|h| h.pose)
            .unwrap_or(self.calibration.default_head)
    }

    /// The scene for the current state and a wand pose (physical frame).
    pub fn scene(&self, wand_physical: Option<Pose>) -> Scene {
        let screen = &self.calibration.screen;
        let corners = [
            screen.lower_left_m,
            screen.lower_right_m,
            screen.upper_right_m(),
            screen.upper_left_m,
        ];
        build_scene(&SceneInputs {
            character: &self.character,
            shape_meshes: &self.shape_meshes,
            posture: &self.posture,
            skeleton_pose: &self.skeleton_pose,
            time_s: self.shown_time_s as f32,
            skin_positions_world: &self.surface.positions_m,
            skin_grid: self.skin_grid,
            vehicle_from_world: self.vehicle.vehicle_from_world(),
            wand_physical,
            screen_corners: corners,
            layers: self.layers,
            skin_opacity: self.skin_opacity,
        })
    }

    /// The skin as it is drawn at `time_s`: interpolated back to it when the simulation has
    /// stepped past it (see [`DeformationModel::surface_mesh_at_into`]); the character's own
    /// skin without a simulation.
    fn draw_surface_at(&mut self, time_s: f64) {
        match &self.model {
            Some(model) => {
                model.surface_mesh_at_into(time_s, &mut self.surface);
                self.skin_grid = model.resolution();
            }
            None => {
                self.surface
                    .positions_m
                    .clone_from(&self.character.skin.positions_m);
                self.skin_grid = (self.character.skin.around, self.character.skin.along);
            }
        }
    }

    /// The skin as drawn at the time last shown (after a change of model or resolution).
    fn refresh_surface(&mut self) {
        self.draw_surface_at(self.shown_time_s);
    }

    fn pose_in_physical(&self, snapshot: &HubSnapshot, role: Role) -> Option<Pose> {
        let pose = snapshot.role(role).pose?;
        let physical = if snapshot.from_desktop(role) {
            pose
        } else {
            self.calibration.tracker.world_from_sensor(&pose)
        };
        physical.is_valid().then_some(physical)
    }

    fn read(&mut self, now: Duration) -> TrackerRead {
        if let Some(timing) = &self.replay_timing {
            let at = if self.reads_this_frame == 0 {
                timing.frame_start
            } else {
                timing.frame_start + timing.period.mul_f64(timing.second_read_fraction)
            };
            timing.clock.set(at);
        }
        self.reads_this_frame = self.reads_this_frame.saturating_add(1);
        let snapshot = self.devices.snapshot();
        let _ = now;
        let timed = |role: Role, this: &Self| {
            let sample = snapshot.role(role);
            let usable = !matches!(sample.state, DeviceState::Lost | DeviceState::Stopped)
                || sample.pose.is_some();
            let pose = if usable {
                this.pose_in_physical(&snapshot, role)
            } else {
                None
            };
            pose.map(|pose| TimedPose {
                pose,
                sampled_at: sample.at.unwrap_or(snapshot.now),
            })
        };
        let mut head = timed(Role::Head, self);
        let mut wand = timed(Role::Wand, self);
        // Wire trackers: the calibration's filter per role, and the pose carried to the time
        // of this read by the role's predictor. The desktop stand-ins are exact already.
        for (role, timed, tracker) in [
            (Role::Head, &mut head, &mut self.head_tracker),
            (Role::Wand, &mut wand, &mut self.wand_tracker),
        ] {
            if let Some(t) = timed.as_mut()
                && !snapshot.from_desktop(role)
            {
                tracker.offer(t.sampled_at, &t.pose);
                if let Some(p) = tracker.pose_at(snapshot.now).filter(Pose::is_valid) {
                    t.pose = p;
                }
            }
        }
        let nav = snapshot.role(Role::Navigation);
        let navigation = nav.at.map(|at| TimedAxes {
            value: nav.axes,
            sampled_at: at,
        });
        let read = TrackerRead {
            read_at: snapshot.now,
            head,
            wand,
            navigation,
        };
        self.last_snapshot = Some(snapshot);
        read
    }

    fn update(&mut self, read: &TrackerRead, sim_target_s: f64) {
        // Vehicle: fly by the navigation axes for the real time since the last update.
        let now = read.read_at;
        if let (Some(last), Some(nav)) = (self.last_update_at, read.navigation) {
            let dt = now.saturating_sub(last).as_secs_f32().min(0.25);
            self.vehicle.fly(nav.value, dt);
        }
        self.last_update_at = Some(now);
        // Events: button edges are for the tools (issue 6); drain them so they do not pile up.
        let _events = self.devices.drain_events();
        // Parameter changes between steps.
        if !self.pending_changes.is_empty() {
            let changes = std::mem::take(&mut self.pending_changes);
            if let Some(model) = &mut self.model {
                for change in &changes {
                    if let Err(e) = model.apply(change) {
                        tracing::warn!("{e}");
                        self.sim_error = Some(e.to_string());
                    }
                }
            }
        }
        // Posture at the time the frame will show (for the skeleton and shapes).
        self.posture_at(sim_target_s);
    }

    fn posture_at(&mut self, time_s: f64) {
        match self.motion.and_then(|m| self.character.motions.get(m)) {
            Some(motion) => motion.posture_at_into(time_s, &mut self.posture),
            None => self.posture = Posture::neutral(&self.character.skeleton),
        }
        if self.posture.is_finite() {
            self.character
                .skeleton
                .forward_kinematics_into(&self.posture, &mut self.skeleton_pose);
        }
    }

    fn simulate(&mut self, clock: &dyn Clock, target_s: f64, budget: Duration) -> SimProgress {
        let Some(model) = &mut self.model else {
            return SimProgress::default();
        };
        let start = clock.now();
        let deadline = start.checked_add(budget);
        let mut last_attempt = start;
        let mut attempt_cost = Duration::ZERO;
        let mut may_step = || {
            let now = clock.now();
            attempt_cost = attempt_cost.max(now.saturating_sub(last_attempt));
            last_attempt = now;
            match deadline {
                None => true,
                Some(d) => now + attempt_cost <= d,
            }
        };
        let character = &self.character;
        let motion = self.motion.and_then(|m| character.motions.get(m));
        let neutral = Posture::neutral(&character.skeleton);
        let mut poses = |t: f64, out: &mut Posture| match motion {
            Some(m) => m.posture_at_into(t, out),
            None => out.clone_from(&neutral),
        };
        // Steps are not shortened to land on the frame's time: the skin is drawn there by
        // interpolation (`render`), and landing every frame would cap the steps near 11 ms at
        // 60 Hz (docs/simulate.md, `--free-steps`).
        let report = model.advance_past(
            target_s,
            f64::INFINITY,
            &mut poses as &mut dyn PoseSource,
            &mut may_step,
            Some(clock),
        );
        self.table1.totals.merge(&report);
        let stalled = report.end == AdvanceEnd::Stalled;
        if stalled {
            if self.sim_stalled_at_s.is_none() {
                tracing::warn!(
                    "the simulation stalled at t = {:.4} s: every attempt was non-finite or \
                     exploding ({})",
                    report.time_s,
                    crate::sim::surface::stall_advice(self.integrator)
                );
            }
            self.sim_stalled_at_s = Some(report.time_s);
        } else if report.steps > 0 {
            self.sim_stalled_at_s = None;
        }
        SimProgress {
            steps: u32::try_from(report.steps).unwrap_or(u32::MAX),
            rejected: u32::try_from(report.rejected_steps).unwrap_or(u32::MAX),
            sim_time_s: report.time_s,
            stalled,
        }
    }

    fn set_skin_points(&mut self, points: u32) {
        let Some(model) = &mut self.model else {
            return;
        };
        let (around, along) = grid_for_points(
            points,
            self.character.skin.around,
            self.character.skin.along,
        );
        if model.resolution() == (around, along) {
            return;
        }
        match model.set_resolution(around, along) {
            Ok(()) => self.refresh_surface(),
            Err(e) => {
                tracing::warn!("{e}");
                self.sim_error = Some(e.to_string());
            }
        }
    }
}

/// The grid `(around, along)` with about `points` points and the aspect of `around × along`.
pub fn grid_for_points(points: u32, around: u32, along: u32) -> (u32, u32) {
    let ratio = f64::from(around.max(1)) / f64::from(along.max(1));
    let along_new = (f64::from(points) / ratio).sqrt().round().max(3.0);
    let around_new = (f64::from(points) / along_new).round().max(3.0);
    (around_new as u32, along_new as u32)
}

/// A vehicle that shows the whole character through the calibrated screen.
pub fn frame_character(
    character: &Character,
    pose: &SkeletonPose,
    calibration: &CalibrationProfile,
) -> Vehicle {
    let points = character
        .skin
        .positions_m
        .iter()
        .copied()
        .chain(pose.world_from_joint.iter().map(|p| p.position_m))
        .filter(|p| p.is_finite());
    let (lo, hi) = points.fold(
        (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
        |(lo, hi), p| (lo.min(p), hi.max(p)),
    );
    let screen = &calibration.screen;
    let viewer_distance_m = screen
        .distance_in_front_m(calibration.default_head.position_m)
        .max(0.1);
    if lo.x > hi.x {
        return Vehicle::new(Pose::IDENTITY);
    }
    Vehicle::framing(
        (lo + hi) * 0.5,
        hi - lo,
        screen.center_m(),
        [screen.width_m(), screen.height_m()],
        viewer_distance_m,
    )
}

/// One frame's work: the state, the renderer and the clock the scheduler reads.
pub struct AppFrame<'a> {
    /// The state.
    pub state: &'a mut AppState,
    /// The renderer.
    pub renderer: &'a mut dyn FrameRenderer,
    /// The scheduler's clock (also used to time the simulation's phases).
    pub clock: &'a dyn Clock,
    /// This frame's render: `None` if none was attempted (no eye views yet), else how it went.
    pub rendered: Option<Result<(), String>>,
}

impl FrameWork for AppFrame<'_> {
    fn read_trackers(&mut self, now: Duration) -> TrackerRead {
        self.state.read(now)
    }

    fn update(&mut self, read: &TrackerRead, sim_target_s: f64) {
        self.state.update(read, sim_target_s);
    }

    fn skin_deforming(&self) -> bool {
        self.state.simulation_on && self.state.model.is_some()
    }

    fn simulate(&mut self, target_sim_s: f64, budget: Duration) -> SimProgress {
        self.state.simulate(self.clock, target_sim_s, budget)
    }

    fn set_skin_points(&mut self, points: u32) {
        self.state.set_skin_points(points);
    }

    fn render(&mut self, read: &TrackerRead, shown_time_s: f64) {
        let state = &mut *self.state;
        state.reads_this_frame = 0;
        state.shown_time_s = shown_time_s;
        // The skeleton, the shapes and the skin are all drawn at the time shown: the frame's
        // target, or where the simulation stopped when it lags (see `Scheduler::run_frame`).
        state.posture_at(shown_time_s);
        state.draw_surface_at(shown_time_s);
        let head = state.head_physical(read);
        match eye_views(&state.calibration, &head, &state.view_settings) {
            Ok(views) => state.last_views = Some(views),
            Err(e) => tracing::debug!("eye views: {e}; keeping the last good ones"),
        }
        let Some(views) = state.last_views else {
            return;
        };
        let scene_start = self.clock.now();
        let scene = state.scene(read.wand.map(|w| w.pose));
        state.last_scene_wall = self.clock.now().saturating_sub(scene_start);
        let frame_index = state.scheduler_frames_hint();
        self.rendered = Some(
            self.renderer
                .render(&scene, &views, &state.output, frame_index),
        );
    }
}

impl AppState {
    fn scheduler_frames_hint(&self) -> u64 {
        self.last_record.as_ref().map_or(0, |r| r.frame + 1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::app::scheduler::{Pacing, SchedulerConfig};
    use crate::devices::desktop::DesktopEvent;
    use crate::devices::profile::Profile;
    use crate::devices::replay::ClockedReplay;
    use crate::devices::session::{Record, Session};
    use std::sync::Arc;

    fn torso16() -> Character {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("assets/characters/torso_16.toml");
        Character::load(&path).expect("torso_16")
    }

    struct Recorder(Vec<(Scene, StereoViews)>);

    impl FrameRenderer for Recorder {
        fn render(
            &mut self,
            scene: &Scene,
            views: &StereoViews,
            _output: &OutputSettings,
            _frame_index: u64,
        ) -> Result<(), String> {
            self.0.push((scene.clone(), *views));
            Ok(())
        }
    }

    fn state_with(session: Session, clock: &VirtualClock) -> AppState {
        let character = torso16();
        let model = crate::app::setup::surface_model(&character, IntegratorKind::Verlet);
        let devices = ClockedReplay::new(session, Arc::new(clock.clone())).expect("replay");
        let scheduler = Scheduler::new(
            SchedulerConfig {
                pacing: Pacing::Offline,
                ..SchedulerConfig::default()
            },
            0.0,
        )
        .expect("scheduler");
        AppState::new(
            character,
            model,
            CalibrationProfile::default(),
            Box::new(devices),
            scheduler,
        )
    }

    #[test]
    fn grids_keep_the_aspect_and_the_point_count() {
        assert_eq!(grid_for_points(1024, 32, 32), (32, 32));
        assert_eq!(grid_for_points(256, 32, 32), (16, 16));
        let (m, n) = grid_for_points(576, 32, 16);
        assert!((m * n).abs_diff(576) < 40 && m > n);
        assert!(grid_for_points(1, 4, 4).0 >= 3);
    }

    #[test]
    fn changed_parameters_become_parameter_changes() {
        let character = torso16();
        let before = CharacterParams::of(&character);
        assert!(before.point_mass_kg > 0.0);
        assert!(before.changes_to(&before, &character).is_empty());
        let after = CharacterParams {
            fat_m: before.fat_m + 0.01,
            elasticity_scale: 2.0,
            ..before
        };
        let changes = before.changes_to(&after, &character);
        assert_eq!(changes.len(), 2);
        assert!(changes.iter().any(|c| matches!(c, ParameterChange::Fat(Selection::All, v) if (*v - after.fat_m).abs() < 1e-7)));
        let base = mean_sym2(&character.skin.stretch);
        assert!(changes.iter().any(|c| matches!(c, ParameterChange::Stretch(Selection::All, s) if (s[0] - 2.0 * base[0]).abs() < 1e-3 * base[0].abs().max(1.0))));
    }

    #[test]
    fn without_a_head_tracker_the_view_is_from_the_calibrated_position_and_the_mouse_moves_the_wand()
     {
        // A desktop session: the mouse moves to the right edge at 0.1 s.
        let mut session = Session::new(Profile::desktop_default());
        session.records.push(Record::Opened {
            at: Duration::ZERO,
            device: 0,
        });
        session.records.push(Record::Desktop {
            at: Duration::from_millis(100),
            event: DesktopEvent::MouseMove { x: 1.0, y: 0.5 },
        });
        let clock = VirtualClock::new();
        let mut state = state_with(session, &clock);
        let mut renderer = Recorder(Vec::new());
        let period = Duration::from_micros(16_667);
        let mut wand_x = Vec::new();
        for n in 0..12u32 {
            state.replay_timing = Some(ReplayTiming {
                clock: clock.clone(),
                frame_start: period * n,
                period,
                second_read_fraction: 0.75,
            });
            let record = state.run_frame(&clock, &mut renderer);
            assert!(record.sim_steps > 0);
            let (scene, views) = renderer.0.last().expect("rendered");
            // The desktop head sits at the calibration's viewing position.
            let centre = views.center.position_m;
            assert!(
                (centre - Vec3::new(0.0, 0.0, 0.6)).length() < 1e-4,
                "{centre}"
            );
            let wand = scene.wand.expect("wand drawn");
            wand_x.push(wand.world_from_wand.w_axis.x);
            assert!(scene.skin.is_some());
        }
        // The cursor moved from the centre to the right edge of the 0.4 m wand area.
        assert!(wand_x[0].abs() < 1e-5);
        assert!((wand_x[11] - 0.2).abs() < 1e-4, "{wand_x:?}");
    }

    #[test]
    fn the_scheduler_changes_the_skin_resolution_of_the_real_model() {
        let clock = VirtualClock::new();
        let mut state = state_with(Session::new(Profile::desktop_default()), &clock);
        let (m, n) = state.skin_grid();
        assert_eq!(m * n, 256);
        state.set_skin_points(64);
        assert_eq!(state.skin_grid(), (8, 8));
        assert_eq!(state.surface().positions_m.len(), 64);
        assert!(state.sim_error.is_none(), "{:?}", state.sim_error);
        let mut renderer = Recorder(Vec::new());
        let record = state.run_frame(&clock, &mut renderer);
        assert!(record.sim_steps > 0);
        let (scene, _) = renderer.0.last().expect("rendered");
        // The display draws the 8×8 grid refined (render::subdivide).
        let level = crate::render::subdivide::display_level(8);
        let (rm, rn) = crate::render::subdivide::refined_size(8, 8, level);
        assert_eq!(
            scene.skin.as_ref().expect("skin").mesh.positions.len(),
            (rm * rn) as usize
        );
    }
}
