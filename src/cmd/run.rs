//! `leman run` (and plain `leman`): opens the workstation window on the default character with
//! the default calibration and the devices of a profile (when no profile is given, the desktop
//! mouse and keyboard, with a HID SpaceMouse flying the view once plugged in:
//! `devices::found`), recording them with `--record`.

use anyhow::Context;
use leman::app::scheduler::{Pacing, Scheduler, SchedulerConfig};
use leman::app::setup;
use leman::app::state::AppState;
use leman::calibration::CalibrationProfile;
use leman::character::Character;
use leman::clock::{RealClock, VirtualClock};
use leman::devices::desktop::DesktopEvent;
use leman::devices::hub::{Hub, HubOptions, HubSnapshot, TimedEvent};
use leman::devices::profile::Profile;
use leman::devices::replay::{ClockedReplay, DeviceSource};
use leman::devices::session::Session;
use leman::sim::IntegratorKind;
use leman::stereo::StereoMode;
use leman::ui::window::WorkstationApp;
use std::path::PathBuf;
use std::sync::Arc;

/// Arguments of `leman run`.
#[derive(Debug, Default, clap::Args)]
pub struct Args {
    /// Character file (default: assets/characters/torso.toml).
    #[arg(long)]
    pub character: Option<PathBuf>,
    /// Device profile (TOML); default: the desktop mouse and keyboard, with any supported
    /// SpaceMouse (USB HID) flying the view while it is plugged in.
    #[arg(long)]
    pub profile: Option<PathBuf>,
    /// Calibration profile (default: the built-in desktop).
    #[arg(long)]
    pub calibration: Option<PathBuf>,
    /// Stereo mode: mono, sbs, sbs-full, top-bottom, anaglyph, rows, sequential.
    #[arg(long)]
    pub stereo: Option<String>,
    /// Simulated seconds per real second (1 = real time, lower = slow motion).
    #[arg(long, default_value_t = 1.0)]
    pub ratio: f64,
    /// Close the window after this many frames (for tests and screenshots).
    #[arg(long, hide = true)]
    pub quit_after_frames: Option<u64>,
    /// Window size, WIDTHxHEIGHT.
    #[arg(long)]
    pub size: Option<String>,
    /// Write the per-frame log (JSON lines) to this file when the window closes.
    #[arg(long)]
    pub log: Option<PathBuf>,
    /// Lower and raise the skin resolution to hold the sim/real ratio.
    #[arg(long)]
    pub adapt: bool,
    /// Record the devices, the mouse and keyboard included, into this session file while the
    /// window is open (written as `leman record` writes, finished when the window closes;
    /// play it back with `leman replay`).
    #[arg(long, value_name = "SESSION")]
    pub record: Option<PathBuf>,
    /// Replace `--record` if it exists (without this, an existing file is refused).
    #[arg(long)]
    pub overwrite: bool,
}

/// What the window needs.
pub struct WindowSetup {
    /// The character.
    pub character: Character,
    /// The calibration.
    pub calibration: CalibrationProfile,
    /// Stereo mode.
    pub mode: StereoMode,
    /// A session to replay instead of live devices.
    pub replay: Option<Session>,
    /// A device profile for live devices (desktop when none).
    pub profile: Option<Profile>,
    /// Sim/real ratio.
    pub ratio: f64,
    /// Adapt the skin resolution.
    pub adapt: bool,
    /// Where to write the frame log at exit.
    pub log: Option<PathBuf>,
    /// Where to record the live devices (not with `replay`).
    pub record_to: Option<PathBuf>,
}

/// Runs `leman run`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let character = setup::load_character(args.character.as_deref())?;
    let calibration = setup::load_calibration(args.calibration.as_deref())?;
    let mode = match &args.stereo {
        Some(s) => setup::parse_stereo_mode(s)?,
        None => StereoMode::Mono,
    };
    if let Some(path) = &args.record {
        super::refuse_existing("--record", path, args.overwrite)?;
    }
    let profile = match &args.profile {
        Some(p) => Profile::load(p)?,
        None => {
            // The desktop stand-ins and any SpaceMouse, now or later (leman::devices::found);
            // the listing only tells the user what is there at start.
            let hid = leman::devices::enumerate::list_hid().unwrap_or_else(|e| {
                eprintln!("warning: cannot list HID devices ({e})");
                Vec::new()
            });
            eprintln!("{}", leman::devices::found::summary(&hid));
            leman::devices::found::default_profile()
        }
    };
    let size = match &args.size {
        Some(s) => setup::parse_size(s)?,
        None => [1600, 900],
    };
    run_window_sized(
        WindowSetup {
            character,
            calibration,
            mode,
            replay: None,
            profile: Some(profile),
            ratio: args.ratio,
            adapt: args.adapt,
            log: args.log.clone(),
            record_to: args.record.clone(),
        },
        size,
        args.quit_after_frames,
    )
}

/// Opens the window (used by `run` and `replay` without `--headless`).
pub fn run_window(setup: WindowSetup) -> anyhow::Result<()> {
    run_window_sized(setup, [1600, 900], None)
}

fn run_window_sized(
    setup: WindowSetup,
    size: [u32; 2],
    quit_after_frames: Option<u64>,
) -> anyhow::Result<()> {
    let WindowSetup {
        character,
        calibration,
        mode,
        replay,
        profile,
        ratio,
        adapt,
        log,
        record_to,
    } = setup;
    let model = setup::surface_model(&character, IntegratorKind::Verlet);
    if let Err(e) = &model {
        eprintln!("warning: the skin will not be simulated: {e}");
    }
    // A replay in the window runs on its own clock, advanced in real time by the frames. A
    // recording hub is kept here too, to finish the session once the window has closed.
    let mut recording_hub = None;
    let (devices, replay_clock): (Box<dyn DeviceSource>, Option<VirtualClock>) = match replay {
        Some(session) => {
            let clock = VirtualClock::new();
            let source = ClockedReplay::new(session, Arc::new(clock.clone()))?;
            (Box::new(source), Some(clock))
        }
        None => {
            let profile = profile.unwrap_or_else(Profile::desktop_default);
            let recording = record_to.is_some();
            let hub = Arc::new(
                Hub::start(
                    profile,
                    Arc::new(RealClock::new()),
                    HubOptions { record_to },
                )
                .context("starting the device hub")?,
            );
            recording_hub = recording.then(|| Arc::clone(&hub));
            (Box::new(SharedHub(hub)), None)
        }
    };
    let config = SchedulerConfig {
        sim_per_real: ratio,
        pacing: Pacing::Live,
        adapt,
        ..SchedulerConfig::default()
    };
    let scheduler = Scheduler::new(config, 0.0)?;
    let mut state = AppState::new(character, model, calibration, devices, scheduler);
    state.output.mode = mode;
    let options = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default()
            .with_title("leman")
            .with_inner_size([size[0] as f32, size[1] as f32]),
        ..Default::default()
    };
    eframe::run_native(
        "leman",
        options,
        Box::new(move |cc| {
            let mut app = WorkstationApp::new(cc, state);
            app.quit_after_frames = quit_after_frames;
            app.log_path = log;
            if let Some(clock) = replay_clock {
                app.replay_clock = Some((clock, RealClock::new()));
            }
            Ok(Box::new(app))
        }),
    )
    .map_err(|e| anyhow::anyhow!("window: {e}"))?;
    if let Some(hub) = recording_hub {
        finish_recording(hub)?;
    }
    Ok(())
}

/// A hub the window reads while `run_window_sized` may keep it too, to finish its recording.
struct SharedHub(Arc<Hub>);

impl DeviceSource for SharedHub {
    fn snapshot(&self) -> HubSnapshot {
        self.0.snapshot()
    }
    fn drain_events(&self) -> Vec<TimedEvent> {
        self.0.drain_events()
    }
    fn feed_desktop(&self, event: DesktopEvent) -> bool {
        self.0.feed_desktop(event)
    }
}

/// Stops the recording hub once the window (and with it the app's handle) is gone, writing the
/// session's end and renaming it into place.
fn finish_recording(hub: Arc<Hub>) -> anyhow::Result<()> {
    if let Some(e) = hub.record_error() {
        anyhow::bail!(
            "recording failed: {e} (recover what was written with leman record --recover)"
        );
    }
    let hub = Arc::try_unwrap(hub).map_err(|_| {
        anyhow::anyhow!(
            "the recording could not be finished: the window still holds the device hub \
             (recover the .partial file with leman record --recover)"
        )
    })?;
    if let Some(path) = hub.stop()? {
        eprintln!("recorded {}", path.display());
    }
    Ok(())
}
