//! The frame scheduler: LEMAN's decoupled frame time-line (paper `003_…`, section 5.2, Figure 5).
//!
//! Every frame:
//! 1. read the newest head, wand and navigation samples;
//! 2. move the vehicle, handle events, run the active tool;
//! 3. while the skin is deforming, take simulation steps until the time left in the frame is no
//!    more than the previous frame's render time (and the simulation has caught up with the
//!    time it should show);
//! 4. read the trackers again;
//! 5. render with the newest (second) poses.
//!
//! The scheduler is pure: it reads time only from the [`Clock`] it is handed, and does the work
//! through a [`FrameWork`], so tests drive it with a `VirtualClock` and fake costs.
//!
//! Simulated time versus real time: the user sets `sim_per_real` (1 = real time, 0.25 = four
//! times slower). Each frame the simulation's target time moves on by `sim_per_real` times the
//! real time since the previous frame. When the machine cannot keep up, the lag is forgiven
//! beyond one frame's worth (so the skin never tries to "catch up" in a burst), the measured
//! ratio drops and the scheduler says so ([`SchedulerEvent::RatioNotHeld`]). With
//! [`SchedulerConfig::adapt`] on, it lowers the skin resolution to hold the ratio and raises it
//! again once the cost predicted at the higher resolution fits the budget with a margin
//! (hysteresis), which is the future work named in the paper's conclusion.

use crate::clock::Clock;
use crate::pose::Pose;
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;
use std::time::Duration;

/// How frames are paced.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Pacing {
    /// Live: real time between frames drives the simulation target, and the simulation gets
    /// only the time left in the frame minus the previous render time.
    Live,
    /// Offline (headless replay, baking): each frame is exactly one frame period of session
    /// time, and the simulation always reaches its target, however long that takes. The frames
    /// are then the same on any machine; the wall times are still measured and logged.
    Offline,
}

/// Settings of the scheduler.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SchedulerConfig {
    /// The display's frame period (1/60 s at 60 Hz).
    pub frame_period: Duration,
    /// Simulated seconds per real second (1 = real time, lower = slow motion). Must be > 0.
    pub sim_per_real: f64,
    /// Live or offline pacing.
    pub pacing: Pacing,
    /// Lower and raise the skin resolution to hold the ratio (live pacing only).
    pub adapt: bool,
    /// Skin resolutions the adapt setting may choose from, in mass points, ascending.
    pub skin_points_levels: Vec<u32>,
    /// Index into `skin_points_levels` to start at.
    pub start_level: usize,
    /// Real time between frames counted at most this much (a stall is not simulated).
    pub max_real_step: Duration,
    /// The ratio counts as held while the measured ratio is at least `(1 - tolerance)` × set.
    pub ratio_tolerance: f64,
    /// Frames over which the measured ratio is averaged.
    pub ratio_window_frames: usize,
    /// Adapt lowers the resolution after this many frames in a row that fell behind.
    pub lower_after_frames: u32,
    /// Adapt raises the resolution after this many frames in a row where the higher
    /// resolution's predicted cost fits the budget with the margin below.
    pub raise_after_frames: u32,
    /// Fraction of the simulation budget the predicted cost at the higher level may use.
    pub raise_margin: f64,
    /// Least share of a frame the simulation gets when rendering alone takes longer than a
    /// frame period (live pacing): the frame is stretched to
    /// `(work before the simulation + previous render) / (1 - min_sim_fraction)` so the skin
    /// keeps moving on a slow machine instead of starving. 0 is the paper's rule exactly.
    /// Clamped to [0, 0.9].
    pub min_sim_fraction: f64,
}

impl Default for SchedulerConfig {
    fn default() -> Self {
        Self {
            frame_period: Duration::from_micros(16_667),
            sim_per_real: 1.0,
            pacing: Pacing::Live,
            adapt: false,
            skin_points_levels: vec![64, 144, 256, 576, 1024],
            start_level: 4,
            max_real_step: Duration::from_millis(250),
            ratio_tolerance: 0.05,
            ratio_window_frames: 30,
            lower_after_frames: 8,
            raise_after_frames: 30,
            raise_margin: 0.75,
            min_sim_fraction: 0.5,
        }
    }
}

/// A pose with the time its sample arrived (on the frame loop's clock).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TimedPose {
    /// The pose (tracker in world, already through calibration and the vehicle).
    pub pose: Pose,
    /// When the sample arrived.
    pub sampled_at: Duration,
}

/// Navigation axes (Spaceball or keyboard) with their arrival time.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TimedAxes {
    /// Translation x, y, z then rotation x, y, z, each about [-1, 1].
    pub value: [f32; 6],
    /// When the sample arrived.
    pub sampled_at: Duration,
}

/// What one read of the devices returned: the newest sample per role.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct TrackerRead {
    /// When the read happened.
    pub read_at: Duration,
    /// Newest head pose, if any head source exists.
    pub head: Option<TimedPose>,
    /// Newest wand (3D mouse) pose.
    pub wand: Option<TimedPose>,
    /// Newest navigation axes.
    pub navigation: Option<TimedAxes>,
}

/// What a call to [`FrameWork::simulate`] did.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct SimProgress {
    /// Accepted integration steps.
    pub steps: u32,
    /// Rejected (retried) steps.
    pub rejected: u32,
    /// The simulation's time after the call, seconds.
    pub sim_time_s: f64,
    /// The model's guard gave up in this call (every attempt non-finite or exploding): the
    /// simulation cannot move on however much time it gets, so falling behind is not the
    /// machine's fault and the skin resolution is left alone.
    pub stalled: bool,
}

/// The work of one frame, done by the app (or by a fake in tests). The scheduler calls these
/// in the order of the paper's time-line and times each call on its clock.
pub trait FrameWork {
    /// Reads the newest sample of each role now (twice per frame: phase 1 and 4).
    fn read_trackers(&mut self, now: Duration) -> TrackerRead;
    /// Moves the vehicle, handles events, runs the active tool (phase 2).
    fn update(&mut self, read: &TrackerRead, sim_target_s: f64);
    /// True while the skin is being simulated (simulation on and a skin present).
    fn skin_deforming(&self) -> bool;
    /// Advances the simulation towards `target_sim_s`, spending at most about `budget` of wall
    /// time (one or more steps; [`Duration::MAX`] means no limit).
    fn simulate(&mut self, target_sim_s: f64, budget: Duration) -> SimProgress;
    /// Changes the skin resolution (mass points) before the next simulation step.
    fn set_skin_points(&mut self, points: u32);
    /// Renders both eyes with the poses of `read` (phase 5), the character at simulation time
    /// `shown_time_s` (the frame's target, or where the simulation stopped short of it).
    fn render(&mut self, read: &TrackerRead, shown_time_s: f64);
}

/// Something the scheduler reports once, when it happens.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum SchedulerEvent {
    /// The machine cannot hold the set sim/real ratio.
    RatioNotHeld {
        /// The ratio the user set.
        set: f64,
        /// The ratio measured over the window.
        achieved: f64,
    },
    /// The set ratio is held again.
    RatioHeld {
        /// The ratio the user set.
        set: f64,
    },
    /// Adapt changed the skin resolution.
    SkinResolution {
        /// Mass points before.
        from_points: u32,
        /// Mass points now.
        to_points: u32,
    },
}

/// A pose as the log shows it: position, orientation and the age of the sample.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LoggedPose {
    /// Position in metres.
    pub position_m: [f32; 3],
    /// Orientation quaternion x, y, z, w.
    pub orientation_xyzw: [f32; 4],
    /// Read time minus arrival time, seconds.
    pub age_s: f64,
}

/// The poses of one read as logged.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct LoggedRead {
    /// Time of the read on the loop's clock, seconds.
    pub read_at_s: f64,
    /// Head pose, if any.
    pub head: Option<LoggedPose>,
    /// Wand pose, if any.
    pub wand: Option<LoggedPose>,
    /// Age of the newest navigation sample, seconds.
    pub navigation_age_s: Option<f64>,
}

impl LoggedRead {
    fn from_read(read: &TrackerRead) -> Self {
        let log_pose = |p: &TimedPose| LoggedPose {
            position_m: p.pose.position_m.to_array(),
            orientation_xyzw: p.pose.orientation.to_array(),
            age_s: read.read_at.saturating_sub(p.sampled_at).as_secs_f64(),
        };
        Self {
            read_at_s: read.read_at.as_secs_f64(),
            head: read.head.as_ref().map(log_pose),
            wand: read.wand.as_ref().map(log_pose),
            navigation_age_s: read
                .navigation
                .map(|n| read.read_at.saturating_sub(n.sampled_at).as_secs_f64()),
        }
    }
}

/// One line of the per-frame log (serialised as one JSON object per line).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameRecord {
    /// Frame number from 0.
    pub frame: u64,
    /// Frame start on the loop's clock, seconds.
    pub start_s: f64,
    /// Real time counted for this frame (drives the simulation target), seconds.
    pub real_step_s: f64,
    /// Display refreshes missed since the previous frame started.
    pub dropped_frames: u32,
    /// Poses of the first read (phase 1).
    pub first_read: LoggedRead,
    /// Poses of the second read, the ones rendered (phase 4/5).
    pub render_read: LoggedRead,
    /// Whether the skin was simulated this frame.
    pub deforming: bool,
    /// Skin resolution in mass points.
    pub skin_points: u32,
    /// Accepted simulation steps this frame.
    pub sim_steps: u32,
    /// Rejected simulation steps this frame.
    pub sim_rejected: u32,
    /// Simulation time after this frame, seconds: at or past `shown_time_s` (by less than one
    /// step) unless the simulation fell short of its target.
    pub sim_time_s: f64,
    /// The time the skeleton and the skin were drawn at this frame, seconds: the target
    /// (`sim_target_s`), or `sim_time_s` when the simulation fell short of it. 0 in logs
    /// written before it existed.
    #[serde(default)]
    pub shown_time_s: f64,
    /// Simulated time advanced this frame, seconds.
    pub sim_advanced_s: f64,
    /// Where the simulation should be after this frame, seconds.
    pub sim_target_s: f64,
    /// Simulated time given up this frame because the machine could not keep up (or the
    /// simulation stalled), seconds.
    pub sim_lost_s: f64,
    /// The simulation stalled this frame: its guard gave up (see [`SimProgress::stalled`]).
    pub sim_stalled: bool,
    /// Wall time of the simulation steps, seconds.
    pub sim_wall_s: f64,
    /// Wall time of the two tracker reads, seconds.
    pub read_wall_s: f64,
    /// Wall time of phase 2 (vehicle, events, tool), seconds.
    pub update_wall_s: f64,
    /// Wall time of the render, seconds.
    pub render_wall_s: f64,
    /// Part of `render_wall_s` spent building the scene on the CPU (filled in by the app;
    /// 0 when not measured), seconds.
    #[serde(default)]
    pub scene_wall_s: f64,
    /// Wall time of the whole frame's work, seconds.
    pub frame_wall_s: f64,
    /// The sim/real ratio the user set.
    pub ratio_set: f64,
    /// The ratio measured over the last frames.
    pub ratio_achieved: f64,
    /// Whether the set ratio is held.
    pub ratio_held: bool,
    /// What happened this frame.
    pub events: Vec<SchedulerEvent>,
}

impl FrameRecord {
    /// The record as one line of JSON (no trailing newline).
    pub fn to_json_line(&self) -> String {
        // Serialising plain numbers, strings and vectors cannot fail; fall back to an empty
        // object rather than panicking.
        serde_json::to_string(self).unwrap_or_else(|_| String::from("{}"))
    }
}

/// Why a scheduler configuration is rejected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SchedulerError {
    /// The frame period is zero.
    #[error("frame period must be positive")]
    ZeroFramePeriod,
    /// The sim/real ratio is not a positive finite number.
    #[error("sim/real ratio must be positive and finite, got {0}")]
    BadRatio(f64),
    /// No resolution levels, or not ascending.
    #[error("skin resolution levels must be non-empty and ascending")]
    BadLevels,
    /// The start level is out of range.
    #[error("start level {0} is out of range")]
    BadStartLevel(usize),
    /// The least simulation share is not in [0, 0.9].
    #[error("min_sim_fraction must be in [0, 0.9], got {0}")]
    BadSimFraction(f64),
}

/// The frame scheduler's state.
#[derive(Debug, Clone)]
pub struct Scheduler {
    config: SchedulerConfig,
    frame: u64,
    previous_start: Option<Duration>,
    previous_render: Duration,
    step_cost_estimate: Duration,
    sim_time_s: f64,
    sim_target_s: f64,
    level: usize,
    pending_points: Option<u32>,
    window: VecDeque<(f64, f64)>,
    ratio_held: bool,
    behind_frames: u32,
    headroom_frames: u32,
}

impl Scheduler {
    /// A scheduler with `config`, simulation time starting at `sim_time_s`.
    pub fn new(config: SchedulerConfig, sim_time_s: f64) -> Result<Self, SchedulerError> {
        validate(&config)?;
        let level = config.start_level;
        let first_render_reserve = config.frame_period / 4;
        Ok(Self {
            config,
            frame: 0,
            previous_start: None,
            // Until a frame has been rendered, reserve a quarter of the frame for rendering.
            previous_render: first_render_reserve,
            step_cost_estimate: Duration::ZERO,
            sim_time_s: finite_or_zero(sim_time_s),
            sim_target_s: finite_or_zero(sim_time_s),
            level,
            // The model keeps its own resolution until adapt (or `set_level`) changes it.
            pending_points: None,
            window: VecDeque::new(),
            ratio_held: true,
            behind_frames: 0,
            headroom_frames: 0,
        })
    }

    /// The current settings.
    pub fn config(&self) -> &SchedulerConfig {
        &self.config
    }

    /// Sets the sim/real ratio (takes effect next frame). Rejects non-positive values.
    pub fn set_sim_per_real(&mut self, ratio: f64) -> Result<(), SchedulerError> {
        if !(ratio.is_finite() && ratio > 0.0) {
            return Err(SchedulerError::BadRatio(ratio));
        }
        if (ratio - self.config.sim_per_real).abs() > f64::EPSILON {
            self.config.sim_per_real = ratio;
            self.window.clear();
        }
        Ok(())
    }

    /// Turns the adapt setting on or off.
    pub fn set_adapt(&mut self, adapt: bool) {
        self.config.adapt = adapt;
        self.behind_frames = 0;
        self.headroom_frames = 0;
    }

    /// Sets the skin resolution level by hand (applied before the next step).
    pub fn set_level(&mut self, level: usize) -> Result<(), SchedulerError> {
        let points = *self
            .config
            .skin_points_levels
            .get(level)
            .ok_or(SchedulerError::BadStartLevel(level))?;
        if level != self.level {
            self.level = level;
            self.pending_points = Some(points);
        }
        Ok(())
    }

    /// Tells the scheduler the model's current resolution without changing it: the level is
    /// the highest one not above `points` (the lowest if all are above).
    pub fn assume_points(&mut self, points: u32) {
        let levels = &self.config.skin_points_levels;
        self.level = levels.iter().rposition(|&l| l <= points).unwrap_or(0);
        self.pending_points = None;
    }

    /// Moves the simulation clock (after a rewind, a new motion or a restored snapshot).
    pub fn reset_sim_time(&mut self, sim_time_s: f64) {
        self.sim_time_s = finite_or_zero(sim_time_s);
        self.sim_target_s = self.sim_time_s;
        self.window.clear();
    }

    /// The current skin resolution, mass points.
    pub fn skin_points(&self) -> u32 {
        self.config
            .skin_points_levels
            .get(self.level)
            .copied()
            .unwrap_or(0)
    }

    /// Simulation time now, seconds.
    pub fn sim_time_s(&self) -> f64 {
        self.sim_time_s
    }

    /// Whether the set ratio is held.
    pub fn ratio_held(&self) -> bool {
        self.ratio_held
    }

    /// Frames run so far.
    pub fn frames(&self) -> u64 {
        self.frame
    }

    /// Runs one frame of the time-line and returns its log record.
    pub fn run_frame(&mut self, clock: &dyn Clock, work: &mut dyn FrameWork) -> FrameRecord {
        let period = self.config.frame_period;
        let start = clock.now();
        let (real_step, dropped_frames) = match (self.config.pacing, self.previous_start) {
            (Pacing::Live, Some(previous)) => {
                let interval = start.saturating_sub(previous);
                let periods = interval.as_secs_f64() / period.as_secs_f64();
                // Missed refreshes; 10% slack so a frame a little late on a jittery clock does
                // not count as a drop.
                let dropped = (periods - 1.1).ceil().max(0.0) as u32;
                (interval.min(self.config.max_real_step), dropped)
            }
            _ => (period, 0),
        };
        self.previous_start = Some(start);
        let mut events = Vec::new();

        if let Some(points) = self.pending_points.take() {
            work.set_skin_points(points);
        }

        // (1) first read.
        let t = clock.now();
        let first = work.read_trackers(t);
        let mut read_wall = clock.now().saturating_sub(t);

        // The time the simulation should reach by the end of this frame.
        let sim_before = self.sim_time_s;
        self.sim_target_s += self.config.sim_per_real * real_step.as_secs_f64();

        // (2) vehicle, events, tool.
        let t = clock.now();
        work.update(&first, self.sim_target_s);
        let update_wall = clock.now().saturating_sub(t);

        // (3) simulation steps while time is left.
        let deforming = work.skin_deforming();
        let sim_start = clock.now();
        let before_sim = sim_start.saturating_sub(start);
        let share = self.config.min_sim_fraction.clamp(0.0, 0.9);
        let stretched = (before_sim + self.previous_render).div_f64(1.0 - share);
        let deadline = start + period.max(stretched);
        let mut budget_at_sim_start = Duration::ZERO;
        let mut steps = 0u32;
        let mut rejected = 0u32;
        let mut stalled = false;
        if deforming {
            budget_at_sim_start = deadline
                .saturating_sub(sim_start)
                .saturating_sub(self.previous_render);
            let target_eps = 1e-9;
            while self.sim_time_s < self.sim_target_s - target_eps {
                let now = clock.now();
                let budget = match self.config.pacing {
                    Pacing::Offline => Duration::MAX,
                    Pacing::Live => {
                        let left = deadline.saturating_sub(now);
                        // Stop when the time left is no more than the previous render time,
                        // or when the next step would not fit before it.
                        if left <= self.previous_render + self.step_cost_estimate {
                            break;
                        }
                        left - self.previous_render
                    }
                };
                let progress = work.simulate(self.sim_target_s, budget);
                let spent = clock.now().saturating_sub(now);
                steps = steps.saturating_add(progress.steps);
                rejected = rejected.saturating_add(progress.rejected);
                stalled |= progress.stalled;
                if progress.steps > 0 {
                    self.step_cost_estimate = spent / progress.steps;
                }
                let progressed = progress.sim_time_s.is_finite()
                    && progress.sim_time_s > self.sim_time_s
                    && progress.steps > 0;
                if progress.sim_time_s.is_finite() {
                    self.sim_time_s = progress.sim_time_s;
                }
                if !progressed {
                    break;
                }
            }
        } else {
            // Nothing to integrate: the skeleton simply shows the target time.
            self.sim_time_s = self.sim_target_s;
        }
        let sim_wall = clock.now().saturating_sub(sim_start);

        // Hold the ratio: allow up to one frame of lag, forgive anything beyond.
        let allowance = self.config.sim_per_real * period.as_secs_f64();
        let lag = self.sim_target_s - self.sim_time_s;
        let mut sim_lost = 0.0;
        let behind = lag > allowance + 1e-9;
        if behind {
            sim_lost = lag - allowance;
            self.sim_target_s = self.sim_time_s + allowance;
        }
        let advanced = self.sim_time_s - sim_before;
        self.window.push_back((advanced, real_step.as_secs_f64()));
        while self.window.len() > self.config.ratio_window_frames.max(1) {
            self.window.pop_front();
        }
        let achieved = self.achieved_ratio();
        let full_window = self.window.len() >= self.config.ratio_window_frames.max(1);
        let held_now = achieved >= self.config.sim_per_real * (1.0 - self.config.ratio_tolerance);
        if full_window && self.ratio_held && !held_now {
            events.push(SchedulerEvent::RatioNotHeld {
                set: self.config.sim_per_real,
                achieved,
            });
            self.ratio_held = false;
        } else if full_window && !self.ratio_held && held_now {
            events.push(SchedulerEvent::RatioHeld {
                set: self.config.sim_per_real,
            });
            self.ratio_held = true;
        }

        if self.config.adapt && self.config.pacing == Pacing::Live && deforming && !stalled {
            self.adapt(behind, sim_wall, budget_at_sim_start, &mut events);
        }

        // (4) second read, (5) render with it.
        let t = clock.now();
        let second = work.read_trackers(t);
        read_wall += clock.now().saturating_sub(t);
        let t = clock.now();
        // The time drawn: the frame's target, or where the simulation stopped short of it. A
        // simulation may step past its target (by less than one of its steps) and draws its
        // skin interpolated back to this time.
        let shown = self.sim_time_s.min(self.sim_target_s);
        work.render(&second, shown);
        let end = clock.now();
        let render_wall = end.saturating_sub(t);
        self.previous_render = render_wall;

        let record = FrameRecord {
            frame: self.frame,
            start_s: start.as_secs_f64(),
            real_step_s: real_step.as_secs_f64(),
            dropped_frames,
            first_read: LoggedRead::from_read(&first),
            render_read: LoggedRead::from_read(&second),
            deforming,
            skin_points: self.skin_points(),
            sim_steps: steps,
            sim_rejected: rejected,
            sim_time_s: self.sim_time_s,
            shown_time_s: shown,
            sim_advanced_s: advanced,
            sim_target_s: self.sim_target_s,
            sim_lost_s: sim_lost,
            sim_stalled: stalled,
            sim_wall_s: sim_wall.as_secs_f64(),
            read_wall_s: read_wall.as_secs_f64(),
            update_wall_s: update_wall.as_secs_f64(),
            render_wall_s: render_wall.as_secs_f64(),
            scene_wall_s: 0.0,
            frame_wall_s: end.saturating_sub(start).as_secs_f64(),
            ratio_set: self.config.sim_per_real,
            ratio_achieved: achieved,
            ratio_held: self.ratio_held,
            events,
        };
        self.frame += 1;
        record
    }

    fn achieved_ratio(&self) -> f64 {
        let (sim, real) = self
            .window
            .iter()
            .fold((0.0, 0.0), |(s, r), (ds, dr)| (s + ds, r + dr));
        if real > 0.0 { sim / real } else { 0.0 }
    }

    fn adapt(
        &mut self,
        behind: bool,
        sim_wall: Duration,
        budget: Duration,
        events: &mut Vec<SchedulerEvent>,
    ) {
        let levels = &self.config.skin_points_levels;
        if behind {
            self.headroom_frames = 0;
            self.behind_frames += 1;
            if self.behind_frames >= self.config.lower_after_frames && self.level > 0 {
                let from = levels[self.level];
                self.level -= 1;
                let to = levels[self.level];
                self.pending_points = Some(to);
                events.push(SchedulerEvent::SkinResolution {
                    from_points: from,
                    to_points: to,
                });
                self.behind_frames = 0;
                self.step_cost_estimate = Duration::ZERO;
            }
            return;
        }
        self.behind_frames = 0;
        let Some(&next) = levels.get(self.level + 1) else {
            self.headroom_frames = 0;
            return;
        };
        let current = levels[self.level].max(1);
        // Cost grows at least linearly with the number of mass points.
        let predicted = sim_wall.as_secs_f64() * f64::from(next) / f64::from(current);
        if predicted <= self.config.raise_margin * budget.as_secs_f64() {
            self.headroom_frames += 1;
        } else {
            self.headroom_frames = 0;
        }
        if self.headroom_frames >= self.config.raise_after_frames {
            let from = levels[self.level];
            self.level += 1;
            self.pending_points = Some(next);
            events.push(SchedulerEvent::SkinResolution {
                from_points: from,
                to_points: next,
            });
            self.headroom_frames = 0;
            self.step_cost_estimate = Duration::ZERO;
        }
    }
}

fn finite_or_zero(x: f64) -> f64 {
    if x.is_finite() { x } else { 0.0 }
}

fn validate(config: &SchedulerConfig) -> Result<(), SchedulerError> {
    if config.frame_period.is_zero() {
        return Err(SchedulerError::ZeroFramePeriod);
    }
    if !(config.sim_per_real.is_finite() && config.sim_per_real > 0.0) {
        return Err(SchedulerError::BadRatio(config.sim_per_real));
    }
    let levels = &config.skin_points_levels;
    if levels.is_empty() || levels.windows(2).any(|w| w[0] >= w[1]) {
        return Err(SchedulerError::BadLevels);
    }
    if config.start_level >= levels.len() {
        return Err(SchedulerError::BadStartLevel(config.start_level));
    }
    if !(0.0..=0.9).contains(&config.min_sim_fraction) {
        return Err(SchedulerError::BadSimFraction(config.min_sim_fraction));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::clock::VirtualClock;
    use glam::Vec3;

    /// A fake app: every call costs virtual time; the trackers report a pose that moves with
    /// the clock so each read is distinguishable.
    struct FakeWork {
        clock: VirtualClock,
        read_cost: Duration,
        update_cost: Duration,
        render_cost: Duration,
        /// Wall cost of one step per mass point.
        step_cost_per_point: Duration,
        step_sim_s: f64,
        points: u32,
        sim_time_s: f64,
        deforming: bool,
        stalled: bool,
        reads: Vec<TrackerRead>,
        rendered: Vec<TrackerRead>,
        budgets: Vec<Duration>,
    }

    impl FakeWork {
        fn new(clock: &VirtualClock) -> Self {
            Self {
                clock: clock.clone(),
                read_cost: Duration::from_micros(100),
                update_cost: Duration::from_micros(500),
                render_cost: Duration::from_millis(4),
                step_cost_per_point: Duration::from_nanos(1000),
                step_sim_s: 0.002,
                points: 1024,
                sim_time_s: 0.0,
                deforming: true,
                stalled: false,
                reads: Vec::new(),
                rendered: Vec::new(),
                budgets: Vec::new(),
            }
        }
    }

    impl FrameWork for FakeWork {
        fn read_trackers(&mut self, now: Duration) -> TrackerRead {
            self.clock.advance(self.read_cost);
            let x = now.as_secs_f32();
            let read = TrackerRead {
                read_at: now,
                head: Some(TimedPose {
                    pose: Pose::from_translation(Vec3::new(x, 0.0, 0.6)),
                    sampled_at: now.saturating_sub(Duration::from_millis(3)),
                }),
                wand: Some(TimedPose {
                    pose: Pose::from_translation(Vec3::new(0.0, x, 0.3)),
                    sampled_at: now.saturating_sub(Duration::from_millis(5)),
                }),
                navigation: None,
            };
            self.reads.push(read);
            read
        }
        fn update(&mut self, _read: &TrackerRead, _sim_target_s: f64) {
            self.clock.advance(self.update_cost);
        }
        fn skin_deforming(&self) -> bool {
            self.deforming
        }
        fn simulate(&mut self, target_sim_s: f64, budget: Duration) -> SimProgress {
            // One step per call, never past the target.
            self.budgets.push(budget);
            self.clock.advance(self.step_cost_per_point * self.points);
            if self.stalled {
                // Eight failed attempts, and the time they took, for nothing.
                return SimProgress {
                    steps: 0,
                    rejected: 8,
                    sim_time_s: self.sim_time_s,
                    stalled: true,
                };
            }
            let h = self.step_sim_s.min(target_sim_s - self.sim_time_s).max(0.0);
            self.sim_time_s += h;
            SimProgress {
                steps: u32::from(h > 0.0),
                rejected: 0,
                sim_time_s: self.sim_time_s,
                stalled: false,
            }
        }
        fn set_skin_points(&mut self, points: u32) {
            self.points = points;
        }
        fn render(&mut self, read: &TrackerRead, _sim_time_s: f64) {
            self.clock.advance(self.render_cost);
            self.rendered.push(*read);
        }
    }

    /// Waits for the next display refresh, as vsync would.
    fn wait_for_vsync(clock: &VirtualClock, period: Duration) {
        let now = clock.now().as_nanos();
        let p = period.as_nanos();
        let next = now.div_ceil(p) * p;
        clock.set(Duration::from_nanos(next as u64));
    }

    fn run(
        scheduler: &mut Scheduler,
        clock: &VirtualClock,
        work: &mut FakeWork,
        frames: usize,
    ) -> Vec<FrameRecord> {
        (0..frames)
            .map(|_| {
                let r = scheduler.run_frame(clock, work);
                wait_for_vsync(clock, scheduler.config().frame_period);
                r
            })
            .collect()
    }

    #[test]
    fn steps_fit_the_budget_left_after_the_previous_render_time() {
        let clock = VirtualClock::new();
        let mut work = FakeWork::new(&clock);
        // 1024 points at 2 µs each: about 2 ms of wall per 2 ms step, too slow to do 16.7 ms
        // of simulation in the ~12 ms left: the budget binds every frame.
        work.step_cost_per_point = Duration::from_nanos(2000);
        let config = SchedulerConfig::default();
        let period = config.frame_period;
        let mut scheduler = Scheduler::new(config, 0.0).expect("config");
        let records = run(&mut scheduler, &clock, &mut work, 20);
        let step_cost = Duration::from_nanos(2000 * 1024);
        for (i, r) in records.iter().enumerate().skip(1) {
            assert!(r.sim_steps > 0, "frame {i} took no steps");
            let render = Duration::from_secs_f64(records[i - 1].render_wall_s);
            let sim_end = r.start_s + r.read_wall_s / 2.0 + r.update_wall_s + r.sim_wall_s;
            let left = period.as_secs_f64() - (sim_end - r.start_s);
            // Steps fit: the time left is at least the previous render time ...
            assert!(
                left >= render.as_secs_f64() - 1e-9,
                "frame {i}: {left} s left < render {render:?}"
            );
            // ... and no further step would have fit.
            assert!(
                left < (render + step_cost).as_secs_f64() + 1e-9,
                "frame {i}: {left} s left, another step would fit"
            );
            // The frame as a whole fits the period.
            assert!(r.frame_wall_s <= period.as_secs_f64() + 1e-9, "frame {i}");
            assert_eq!(r.dropped_frames, 0);
        }
        // The budget handed to the simulation never included the render reserve.
        let max_budget = period - Duration::from_millis(4);
        assert!(work.budgets.iter().skip(20).all(|b| *b <= max_budget));
    }

    #[test]
    fn a_render_slower_than_the_frame_still_leaves_the_simulation_its_share() {
        let clock = VirtualClock::new();
        let mut work = FakeWork::new(&clock);
        work.render_cost = Duration::from_millis(40); // more than a 16.7 ms frame
        work.step_cost_per_point = Duration::from_nanos(3000); // ~3 ms per 2 ms step
        let mut scheduler = Scheduler::new(SchedulerConfig::default(), 0.0).expect("config");
        let records = run(&mut scheduler, &clock, &mut work, 10);
        for r in &records[1..] {
            assert!(r.sim_steps > 0, "the simulation starved");
            // At least about half of the stretched frame, less one step.
            assert!(
                r.sim_wall_s >= r.render_wall_s * 0.9 - 0.0031,
                "sim {} s vs render {} s",
                r.sim_wall_s,
                r.render_wall_s
            );
            assert!(r.dropped_frames >= 2, "a 60+ ms frame drops refreshes");
        }
        // With the paper's rule alone (share 0) it would starve.
        let clock = VirtualClock::new();
        let mut work = FakeWork::new(&clock);
        work.render_cost = Duration::from_millis(40);
        let config = SchedulerConfig {
            min_sim_fraction: 0.0,
            ..SchedulerConfig::default()
        };
        let mut scheduler = Scheduler::new(config, 0.0).expect("config");
        let records = run(&mut scheduler, &clock, &mut work, 10);
        assert!(records[1..].iter().all(|r| r.sim_steps == 0));
    }

    #[test]
    fn render_uses_the_poses_of_the_second_read() {
        let clock = VirtualClock::new();
        let mut work = FakeWork::new(&clock);
        let mut scheduler = Scheduler::new(SchedulerConfig::default(), 0.0).expect("config");
        let records = run(&mut scheduler, &clock, &mut work, 5);
        assert_eq!(work.reads.len(), 10);
        assert_eq!(work.rendered.len(), 5);
        for (i, r) in records.iter().enumerate() {
            let first = work.reads[2 * i];
            let second = work.reads[2 * i + 1];
            assert_ne!(first, second, "reads of frame {i} must differ in time");
            assert!(second.read_at > first.read_at);
            assert_eq!(work.rendered[i], second);
            // The log shows the rendered poses and their ages.
            let head = r.render_read.head.expect("head logged");
            assert_eq!(
                head.position_m,
                second.head.expect("head").pose.position_m.to_array()
            );
            assert!((head.age_s - 0.003).abs() < 1e-9);
            let wand = r.render_read.wand.expect("wand logged");
            assert!((wand.age_s - 0.005).abs() < 1e-9);
            assert_eq!(r.first_read.read_at_s, first.read_at.as_secs_f64());
            // The render read happens after the simulation.
            assert!(r.render_read.read_at_s >= r.start_s + r.sim_wall_s);
        }
    }

    #[test]
    fn ratio_is_held_when_the_machine_can() {
        for ratio in [1.0, 0.25] {
            let clock = VirtualClock::new();
            let mut work = FakeWork::new(&clock);
            work.step_cost_per_point = Duration::from_nanos(100); // 0.1 ms per step at 1024
            let config = SchedulerConfig {
                sim_per_real: ratio,
                ..SchedulerConfig::default()
            };
            let period = config.frame_period.as_secs_f64();
            let mut scheduler = Scheduler::new(config, 0.0).expect("config");
            let records = run(&mut scheduler, &clock, &mut work, 120);
            let last = records.last().expect("frames");
            let elapsed_real = 120.0 * period;
            assert!(
                (last.sim_time_s - ratio * elapsed_real).abs() < 1e-6,
                "ratio {ratio}: sim {} vs {}",
                last.sim_time_s,
                ratio * elapsed_real
            );
            assert!(records.iter().all(|r| r.ratio_held && r.events.is_empty()));
            assert!((last.ratio_achieved - ratio).abs() < 1e-6);
            assert!(records.iter().all(|r| r.sim_lost_s == 0.0));
        }
    }

    #[test]
    fn machine_too_slow_says_so_once_and_does_not_burst() {
        let clock = VirtualClock::new();
        let mut work = FakeWork::new(&clock);
        work.step_cost_per_point = Duration::from_nanos(2000); // ~2 ms per 2 ms step
        let config = SchedulerConfig::default();
        let mut scheduler = Scheduler::new(config, 0.0).expect("config");
        let records = run(&mut scheduler, &clock, &mut work, 120);
        let not_held: Vec<_> = records
            .iter()
            .flat_map(|r| r.events.iter())
            .filter(|e| matches!(e, SchedulerEvent::RatioNotHeld { .. }))
            .collect();
        assert_eq!(not_held.len(), 1, "reported once, not every frame");
        let last = records.last().expect("frames");
        assert!(!last.ratio_held);
        assert!(last.ratio_achieved < 0.95 && last.ratio_achieved > 0.4);
        // Lag never exceeds one frame of sim time: the rest is given up, not caught up later.
        for r in &records {
            assert!(r.sim_target_s - r.sim_time_s <= 1.0 / 60.0 + 1e-6);
        }
        assert!(records.iter().any(|r| r.sim_lost_s > 0.0));
        // Adapt is off: the resolution stays.
        assert!(records.iter().all(|r| r.skin_points == 1024));
    }

    #[test]
    fn a_stalled_simulation_is_logged_and_does_not_lower_the_resolution() {
        let clock = VirtualClock::new();
        let config = SchedulerConfig {
            adapt: true,
            ..SchedulerConfig::default()
        };
        let mut scheduler = Scheduler::new(config, 0.0).expect("config");
        let mut work = FakeWork::new(&clock);
        work.stalled = true;
        let records = run(&mut scheduler, &clock, &mut work, 60);
        assert!(records.iter().all(|r| r.sim_stalled && r.sim_steps == 0));
        assert!(
            records.iter().all(|r| r.skin_points == 1024),
            "resolution kept"
        );
        assert!(
            !records
                .iter()
                .flat_map(|r| r.events.iter())
                .any(|e| matches!(e, SchedulerEvent::SkinResolution { .. })),
            "no resolution change"
        );
        assert!(records[59].to_json_line().contains("\"sim_stalled\":true"));
        // Once it moves again, the record says so (and a slow machine would adapt again).
        work.stalled = false;
        let records = run(&mut scheduler, &clock, &mut work, 5);
        assert!(records.iter().all(|r| !r.sim_stalled && r.sim_steps > 0));
    }

    #[test]
    fn adapt_lowers_the_resolution_to_hold_the_ratio_and_raises_it_again() {
        let clock = VirtualClock::new();
        let mut work = FakeWork::new(&clock);
        let config = SchedulerConfig {
            adapt: true,
            ..SchedulerConfig::default()
        };
        let mut scheduler = Scheduler::new(config, 0.0).expect("config");
        // Slow machine: 1024 points cannot hold real time (about 2 ms per 2 ms step), 576 can.
        work.step_cost_per_point = Duration::from_nanos(2000);
        let slow = run(&mut scheduler, &clock, &mut work, 200);
        let lowered: Vec<_> = slow
            .iter()
            .flat_map(|r| r.events.iter())
            .filter_map(|e| match e {
                SchedulerEvent::SkinResolution {
                    from_points,
                    to_points,
                } => Some((*from_points, *to_points)),
                _ => None,
            })
            .collect();
        assert!(!lowered.is_empty(), "adapt must lower the resolution");
        assert!(lowered.iter().all(|(from, to)| to < from));
        let settled = slow.last().expect("frames");
        assert!(settled.skin_points < 1024);
        assert!(settled.ratio_held, "ratio held at the lower resolution");
        assert_eq!(
            work.points, settled.skin_points,
            "the work got the new resolution"
        );
        // It settles: no oscillation over the last 100 frames.
        let tail_points = slow[100].skin_points;
        assert!(slow[100..].iter().all(|r| r.skin_points == tail_points));

        // The machine gets ten times faster: adapt raises back to full resolution.
        work.step_cost_per_point = Duration::from_nanos(200);
        let fast = run(&mut scheduler, &clock, &mut work, 300);
        let last = fast.last().expect("frames");
        assert_eq!(last.skin_points, 1024);
        assert!(last.ratio_held);
        let raises = fast
            .iter()
            .flat_map(|r| r.events.iter())
            .filter(|e| matches!(e, SchedulerEvent::SkinResolution { from_points, to_points } if to_points > from_points))
            .count();
        assert!(raises >= 1);
    }

    #[test]
    fn offline_pacing_always_reaches_the_target_whatever_the_cost() {
        let clock = VirtualClock::new();
        let mut work = FakeWork::new(&clock);
        work.step_cost_per_point = Duration::from_micros(10); // 10 ms per step
        let config = SchedulerConfig {
            pacing: Pacing::Offline,
            sim_per_real: 0.5,
            ..SchedulerConfig::default()
        };
        let period = config.frame_period.as_secs_f64();
        let mut scheduler = Scheduler::new(config, 0.0).expect("config");
        let records = run(&mut scheduler, &clock, &mut work, 10);
        for (i, r) in records.iter().enumerate() {
            assert!((r.sim_time_s - 0.5 * period * (i as f64 + 1.0)).abs() < 1e-9);
            assert!(
                r.frame_wall_s > period,
                "the frame took longer than real time"
            );
            assert!(budgets_unlimited(&work.budgets));
        }
    }

    fn budgets_unlimited(budgets: &[Duration]) -> bool {
        budgets.iter().all(|b| *b == Duration::MAX)
    }

    #[test]
    fn not_deforming_takes_no_steps_and_keeps_time() {
        let clock = VirtualClock::new();
        let mut work = FakeWork::new(&clock);
        work.deforming = false;
        let mut scheduler = Scheduler::new(SchedulerConfig::default(), 1.0).expect("config");
        let records = run(&mut scheduler, &clock, &mut work, 6);
        assert!(records.iter().all(|r| r.sim_steps == 0 && !r.deforming));
        assert!(work.budgets.is_empty());
        assert!((records[5].sim_time_s - (1.0 + 6.0 / 60.0)).abs() < 1e-4);
    }

    #[test]
    fn a_stalled_frame_counts_dropped_refreshes() {
        let clock = VirtualClock::new();
        let mut work = FakeWork::new(&clock);
        let mut scheduler = Scheduler::new(SchedulerConfig::default(), 0.0).expect("config");
        let period = scheduler.config().frame_period;
        scheduler.run_frame(&clock, &mut work);
        wait_for_vsync(&clock, period);
        clock.advance(period * 2); // two refreshes missed
        let r = scheduler.run_frame(&clock, &mut work);
        assert_eq!(r.dropped_frames, 2);
    }

    #[test]
    fn log_lines_are_json_objects_with_the_documented_fields() {
        let clock = VirtualClock::new();
        let mut work = FakeWork::new(&clock);
        let mut scheduler = Scheduler::new(SchedulerConfig::default(), 0.0).expect("config");
        let r = scheduler.run_frame(&clock, &mut work);
        let line = r.to_json_line();
        assert!(!line.contains('\n'));
        let v: serde_json::Value = serde_json::from_str(&line).expect("json");
        for key in [
            "frame",
            "render_read",
            "first_read",
            "sim_steps",
            "sim_time_s",
            "sim_wall_s",
            "render_wall_s",
            "dropped_frames",
            "skin_points",
            "ratio_achieved",
        ] {
            assert!(v.get(key).is_some(), "missing {key}");
        }
        let back: FrameRecord = serde_json::from_str(&line).expect("round trip");
        assert_eq!(back, r);
    }

    #[test]
    fn the_model_keeps_its_resolution_until_adapt_changes_it() {
        let clock = VirtualClock::new();
        let mut work = FakeWork::new(&clock);
        work.points = 256;
        work.step_cost_per_point = Duration::from_nanos(100);
        let mut scheduler = Scheduler::new(SchedulerConfig::default(), 0.0).expect("config");
        scheduler.assume_points(256);
        assert_eq!(scheduler.skin_points(), 256);
        let records = run(&mut scheduler, &clock, &mut work, 5);
        assert_eq!(work.points, 256);
        assert!(records.iter().all(|r| r.skin_points == 256));
        scheduler.assume_points(1000);
        assert_eq!(scheduler.skin_points(), 576);
        scheduler.assume_points(10);
        assert_eq!(scheduler.skin_points(), 64);
    }

    #[test]
    fn bad_settings_are_rejected() {
        let bad = |c: SchedulerConfig| Scheduler::new(c, 0.0).is_err();
        assert!(bad(SchedulerConfig {
            sim_per_real: 0.0,
            ..SchedulerConfig::default()
        }));
        assert!(bad(SchedulerConfig {
            sim_per_real: f64::NAN,
            ..SchedulerConfig::default()
        }));
        assert!(bad(SchedulerConfig {
            frame_period: Duration::ZERO,
            ..SchedulerConfig::default()
        }));
        assert!(bad(SchedulerConfig {
            skin_points_levels: vec![256, 64],
            ..SchedulerConfig::default()
        }));
        assert!(bad(SchedulerConfig {
            start_level: 9,
            ..SchedulerConfig::default()
        }));
        assert!(bad(SchedulerConfig {
            min_sim_fraction: f64::NAN,
            ..SchedulerConfig::default()
        }));
        let mut s = Scheduler::new(SchedulerConfig::default(), 0.0).expect("ok");
        assert!(s.set_sim_per_real(-1.0).is_err());
        assert!(s.set_sim_per_real(0.5).is_ok());
    }
}
