//! Headless replay: a recorded device session played through the whole app (devices, vehicle,
//! simulation, stereo, renderer) on a virtual session clock, one frame per frame period, writing
//! PNG frames and the per-frame log as JSON lines.
//!
//! The session clock is virtual: frame `n` reads the devices at `n·period` (first read) and at
//! `n·period + 0.75·period` (second read, "just before rendering"), and the scheduler runs with
//! [`Pacing::Offline`], so the simulation always reaches its target and the frames are the same
//! on any machine. Wall times (simulation, render, reads) are measured on the real clock and
//! logged, which is how the frame-time figures are taken.

use crate::app::gpu::OffscreenStereo;
use crate::app::scheduler::{FrameRecord, Pacing, Scheduler, SchedulerConfig};
use crate::app::state::{AppState, ModelResult, ReplayTiming};
use crate::calibration::CalibrationProfile;
use crate::character::Character;
use crate::clock::{RealClock, VirtualClock};
use crate::devices::replay::ClockedReplay;
use crate::devices::session::Session;
use crate::files::write_atomic;
use crate::render::GpuContext;
use crate::stereo::OutputSettings;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

/// Settings of a headless replay.
#[derive(Debug, Clone)]
pub struct ReplaySettings {
    /// Display size in pixels (the composition may be wider, e.g. full side-by-side).
    pub display_size_px: [u32; 2],
    /// Stereo output.
    pub output: OutputSettings,
    /// Frame period.
    pub frame_period: Duration,
    /// Simulated seconds per real second.
    pub sim_per_real: f64,
    /// Where PNG frames go (none: no frames written).
    pub frames_dir: Option<PathBuf>,
    /// Write every n-th frame as PNG (1 = all).
    pub png_every: u32,
    /// Where the JSON-lines log goes (none: not written).
    pub log_path: Option<PathBuf>,
    /// Run exactly this many frames (none: the session's length). Past the session's end the
    /// devices keep their last samples.
    pub frame_count: Option<u64>,
    /// Simulate the skin.
    pub simulate: bool,
}

impl Default for ReplaySettings {
    fn default() -> Self {
        Self {
            display_size_px: [1280, 720],
            output: OutputSettings::default(),
            frame_period: Duration::from_micros(16_667),
            sim_per_real: 1.0,
            frames_dir: None,
            png_every: 1,
            log_path: None,
            frame_count: None,
            simulate: true,
        }
    }
}

/// What a replay did.
#[derive(Debug, Clone)]
pub struct ReplaySummary {
    /// Frames run.
    pub frames: u64,
    /// PNG files written.
    pub pngs: Vec<PathBuf>,
    /// Every frame's log record.
    pub records: Vec<FrameRecord>,
    /// The render adapter used.
    pub adapter: String,
    /// The integrator of the first frame in which the simulation stalled, if any did (what
    /// the stall advice depends on, [`crate::sim::surface::stall_advice`]).
    pub stall_integrator: Option<crate::sim::ode::IntegratorKind>,
}

/// Why a replay failed.
#[derive(Debug, thiserror::Error)]
pub enum ReplayRunError {
    /// No GPU adapter (install Mesa lavapipe: `apt-get install mesa-vulkan-drivers`).
    #[error("no render device: {0}")]
    Gpu(#[from] crate::render::DeviceError),
    /// The renderer could not be made.
    #[error("renderer: {0}")]
    Render(#[from] crate::render::RenderError),
    /// The session cannot be replayed.
    #[error(transparent)]
    Session(#[from] crate::devices::replay::ReplayError),
    /// Bad scheduler settings.
    #[error(transparent)]
    Scheduler(#[from] crate::app::scheduler::SchedulerError),
    /// A frame or the log could not be written.
    #[error(transparent)]
    Write(#[from] crate::files::WriteError),
    /// The stereo mode's output image at this display size is larger than the render device
    /// allows.
    #[error(
        "a {width}×{height} display in {mode} needs a {out_w}×{out_h} image, but this render device allows at most {max} pixels a side"
    )]
    OutputTooLarge {
        /// The stereo mode's name.
        mode: &'static str,
        /// Display width, pixels.
        width: u32,
        /// Display height, pixels.
        height: u32,
        /// Output image width, pixels.
        out_w: u32,
        /// Output image height, pixels.
        out_h: u32,
        /// The device's limit, pixels.
        max: u32,
    },
    /// A frame could not be encoded or rendered.
    #[error("frame {frame}: {message}")]
    Frame {
        /// Frame number.
        frame: u64,
        /// What went wrong.
        message: String,
    },
}

/// Plays `session` through the app headless.
pub fn replay_headless(
    session: Session,
    character: Character,
    model: ModelResult,
    calibration: CalibrationProfile,
    settings: &ReplaySettings,
) -> Result<ReplaySummary, ReplayRunError> {
    let gpu = GpuContext::new_headless()?;
    let mut renderer = OffscreenStereo::new(&gpu.device, &gpu.queue, settings.display_size_px)?;
    // Every frame would fail to render (and write no PNG): say so before running any.
    let [width, height] = settings.display_size_px;
    let [out_w, out_h] = settings
        .output
        .mode
        .output_size_px(settings.display_size_px);
    let max = renderer.max_output_px();
    if out_w > max || out_h > max {
        return Err(ReplayRunError::OutputTooLarge {
            mode: settings.output.mode.label(),
            width,
            height,
            out_w,
            out_h,
            max,
        });
    }

    let session_clock = VirtualClock::new();
    let duration = session.duration();
    let source = ClockedReplay::new(session, Arc::new(session_clock.clone()))?;
    let config = SchedulerConfig {
        frame_period: settings.frame_period,
        sim_per_real: settings.sim_per_real,
        pacing: Pacing::Offline,
        ..SchedulerConfig::default()
    };
    let scheduler = Scheduler::new(config, 0.0)?;
    let mut state = AppState::new(character, model, calibration, Box::new(source), scheduler);
    state.output = settings.output;
    state.simulation_on = settings.simulate;
    // Offline pacing: keep the character's own resolution.
    let frames = {
        let n = (duration.as_secs_f64() / settings.frame_period.as_secs_f64()).floor() as u64 + 1;
        settings.frame_count.unwrap_or(n)
    };

    // Make the output folders first, so a bad path fails before the frames are run.
    let log_dir = settings
        .log_path
        .as_ref()
        .and_then(|p| p.parent())
        .filter(|d| !d.as_os_str().is_empty())
        .map(Path::to_path_buf);
    for dir in settings.frames_dir.iter().chain(log_dir.iter()) {
        std::fs::create_dir_all(dir).map_err(|source| crate::files::WriteError {
            path: dir.clone(),
            source,
        })?;
    }
    let wall = RealClock::new();
    let mut records = Vec::with_capacity(frames as usize);
    let mut pngs = Vec::new();
    let every = u64::from(settings.png_every.max(1));
    let mut stall_integrator = None;
    for n in 0..frames {
        // Read back only the frames that are written (a readback counts as render time).
        renderer.capture = settings.frames_dir.is_some() && n % every == 0;
        renderer.last_image = None;
        state.replay_timing = Some(ReplayTiming {
            clock: session_clock.clone(),
            frame_start: settings.frame_period * n as u32,
            period: settings.frame_period,
            second_read_fraction: 0.75,
        });
        let record = state.run_frame(&wall, &mut renderer);
        if let (Some(dir), Some(image)) = (&settings.frames_dir, &renderer.last_image) {
            let path = dir.join(format!("frame_{n:05}.png"));
            image.save_png(&path).map_err(|e| ReplayRunError::Frame {
                frame: n,
                message: e.to_string(),
            })?;
            pngs.push(path);
        }
        if record.sim_stalled && stall_integrator.is_none() {
            stall_integrator = Some(state.integrator);
        }
        records.push(record);
    }
    if let Some(path) = &settings.log_path {
        write_log(path, &records)?;
    }
    Ok(ReplaySummary {
        frames,
        pngs,
        records,
        adapter: gpu.summary.to_string(),
        stall_integrator,
    })
}

/// Writes the per-frame log, one JSON object per line, atomically.
pub fn write_log(path: &Path, records: &[FrameRecord]) -> Result<(), crate::files::WriteError> {
    let mut text = String::new();
    for r in records {
        text.push_str(&r.to_json_line());
        text.push('\n');
    }
    write_atomic(path, text.as_bytes())
}

/// Medians of a log's frame parts, seconds: `(frame, sim, render, other)`, where other is the
/// frame's work minus simulation and render (reads, vehicle, events, scene building).
pub fn median_parts(records: &[FrameRecord]) -> Option<(f64, f64, f64, f64)> {
    fn median(mut v: Vec<f64>) -> f64 {
        v.sort_by(f64::total_cmp);
        let n = v.len();
        if n % 2 == 1 {
            v[n / 2]
        } else {
            0.5 * (v[n / 2 - 1] + v[n / 2])
        }
    }
    if records.is_empty() {
        return None;
    }
    let frame = median(records.iter().map(|r| r.frame_wall_s).collect());
    let sim = median(records.iter().map(|r| r.sim_wall_s).collect());
    let render = median(records.iter().map(|r| r.render_wall_s).collect());
    let other = median(
        records
            .iter()
            .map(|r| (r.frame_wall_s - r.sim_wall_s - r.render_wall_s).max(0.0))
            .collect(),
    );
    Some((frame, sim, render, other))
}
