//! `leman replay`: plays a recorded session through the whole app, headless (PNG frames and a
//! JSON-lines frame log) or in the workstation window.

use anyhow::Context;
use leman::app::replay::{ReplaySettings, median_parts, replay_headless};
use leman::app::setup;
use leman::devices::session::Session;
use leman::sim::IntegratorKind;
use leman::stereo::OutputSettings;
use std::path::PathBuf;
use std::time::Duration;

/// Arguments of `leman replay`.
#[derive(Debug, Default, clap::Args)]
pub struct Args {
    /// The recorded session file.
    pub session: PathBuf,
    /// Run without a window, writing frames and the log.
    #[arg(long)]
    pub headless: bool,
    /// Folder for PNG frames (headless).
    #[arg(long)]
    pub frames: Option<PathBuf>,
    /// Write every n-th frame only.
    #[arg(long, default_value_t = 1)]
    pub every: u32,
    /// The per-frame log, JSON lines (default: `frames.jsonl` in the frames folder).
    #[arg(long)]
    pub log: Option<PathBuf>,
    /// Character file (default: assets/characters/torso.toml).
    #[arg(long)]
    pub character: Option<PathBuf>,
    /// Calibration profile (default: the built-in desktop).
    #[arg(long)]
    pub calibration: Option<PathBuf>,
    /// Stereo mode: mono, sbs, sbs-full, top-bottom, anaglyph, rows, sequential.
    #[arg(long, default_value = "mono")]
    pub stereo: String,
    /// Display size, WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x720")]
    pub size: String,
    /// Frames per second of session time.
    #[arg(long, default_value_t = 60.0)]
    pub fps: f64,
    /// Simulated seconds per real second (1 = real time, lower = slow motion).
    #[arg(long, default_value_t = 1.0)]
    pub ratio: f64,
    /// Run exactly this many frames (default: the session's length; past its end the devices
    /// keep their last samples).
    #[arg(long)]
    pub frame_count: Option<u64>,
    /// Do not simulate the skin.
    #[arg(long)]
    pub no_sim: bool,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Runs `leman replay`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let session = Session::load(&args.session)?;
    let character = setup::load_character(args.character.as_deref())?;
    let calibration = setup::load_calibration(args.calibration.as_deref())?;
    let mode = setup::parse_stereo_mode(&args.stereo)?;
    let size = setup::parse_size(&args.size)?;
    if !(args.fps.is_finite() && args.fps > 0.0 && args.fps <= 1000.0) {
        anyhow::bail!("--fps must be in (0, 1000], got {}", args.fps);
    }
    if !args.headless {
        return super::run::run_window(super::run::WindowSetup {
            character,
            calibration,
            mode,
            replay: Some(session),
            profile: None,
            ratio: args.ratio,
            adapt: false,
            log: args.log.clone(),
            record_to: None,
        });
    }
    let log = args
        .log
        .clone()
        .or_else(|| args.frames.as_ref().map(|d| d.join("frames.jsonl")));
    let settings = ReplaySettings {
        display_size_px: size,
        output: OutputSettings {
            mode,
            swap_eyes: false,
        },
        frame_period: Duration::from_secs_f64(1.0 / args.fps),
        sim_per_real: args.ratio,
        frames_dir: args.frames.clone(),
        png_every: args.every.max(1),
        log_path: log.clone(),
        frame_count: args.frame_count,
        simulate: !args.no_sim,
    };
    let model = setup::surface_model(&character, IntegratorKind::Verlet);
    if let Err(e) = &model {
        eprintln!("warning: the skin will not be simulated: {e}");
    }
    let summary = replay_headless(session, character, model, calibration, &settings)
        .with_context(|| format!("replaying {}", args.session.display()))?;
    let parts = median_parts(&summary.records);
    let stalled_frames = summary.records.iter().filter(|r| r.sim_stalled).count();
    if args.json {
        let (frame, sim, render, other) = parts.unwrap_or_default();
        let v = serde_json::json!({
            "frames": summary.frames,
            "pngs": summary.pngs.len(),
            "log": log,
            "adapter": summary.adapter,
            "median_s": {"frame": frame, "sim": sim, "render": render, "other": other},
            "stalled_frames": stalled_frames,
        });
        println!("{v}");
    } else {
        println!(
            "replayed {} frames on {}; {} PNG frames{}",
            summary.frames,
            summary.adapter,
            summary.pngs.len(),
            log.map(|l| format!(", log {}", l.display()))
                .unwrap_or_default()
        );
        if let Some((frame, sim, render, other)) = parts {
            println!(
                "median per frame: {:.2} ms = sim {:.2} ms + render {:.2} ms + other {:.2} ms",
                frame * 1e3,
                sim * 1e3,
                render * 1e3,
                other * 1e3
            );
        }
        let first = summary.records.iter().find(|r| r.sim_stalled);
        if let (Some(first), Some(kind)) = (first, summary.stall_integrator) {
            println!(
                "warning: the simulation stalled in {} of {} frames, first at t = {:.4} s (every \
                 attempt non-finite or exploding: {})",
                stalled_frames,
                summary.frames,
                first.sim_time_s,
                leman::sim::surface::stall_advice(kind)
            );
        }
    }
    Ok(())
}
