//! `leman record`: records live devices into a session file until Ctrl-C.

use anyhow::Context as _;
use leman::clock::RealClock;
use leman::devices::hub::{DeviceState, Hub, HubOptions};
use leman::devices::profile::Profile;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// Arguments of `leman record`.
#[derive(Debug, Default, clap::Args)]
pub struct Args {
    /// Device profile (TOML, see devices/*.toml and docs/sessions.md).
    #[arg(long)]
    pub profile: Option<PathBuf>,
    /// Session file to write (written under a temporary name, renamed into place on stop).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Stop by itself after this many seconds (default: run until Ctrl-C).
    #[arg(long)]
    pub seconds: Option<f64>,
    /// Print each device's state and rate every this many seconds (0 = never).
    #[arg(long, default_value_t = 1.0)]
    pub status_every: f64,
}

/// Runs `leman record`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let profile_path = args
        .profile
        .context("--profile FILE is required (see devices/*.toml)")?;
    let out = args.out.context("--out SESSION is required")?;
    let profile = Profile::load(&profile_path)?;
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = Arc::clone(&stop);
        ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst))
            .context("cannot install the Ctrl-C handler")?;
    }
    let hub = Hub::start(
        profile,
        Arc::new(RealClock::new()),
        HubOptions {
            record_to: Some(out.clone()),
        },
    )?;
    eprintln!(
        "recording to {} (Ctrl-C to stop{})",
        out.display(),
        args.seconds
            .map(|s| format!(", or after {s} s"))
            .unwrap_or_default()
    );
    let started = Instant::now();
    let limit = args
        .seconds
        .filter(|s| s.is_finite() && *s >= 0.0)
        .map(Duration::from_secs_f64);
    let every = (args.status_every.is_finite() && args.status_every > 0.0)
        .then(|| Duration::from_secs_f64(args.status_every));
    let mut last_status = Instant::now();
    while !stop.load(Ordering::SeqCst) && limit.is_none_or(|l| started.elapsed() < l) {
        std::thread::sleep(Duration::from_millis(20));
        if let Some(every) = every
            && last_status.elapsed() >= every
        {
            last_status = Instant::now();
            for d in hub.snapshot().devices {
                let detail = match d.state {
                    DeviceState::Lost => d.last_error.unwrap_or_default(),
                    _ => format!("{:.0} samples/s, {} bytes", d.rate_hz, d.bytes),
                };
                eprintln!("  {} ({}): {:?} {}", d.name, d.protocol, d.state, detail);
            }
        }
    }
    if let Some(e) = hub.record_error() {
        anyhow::bail!("recording failed: {e}");
    }
    let snap = hub.snapshot();
    let path = hub.stop()?;
    let chunks: u64 = snap.devices.iter().map(|d| d.chunks).sum();
    if let Some(path) = path {
        eprintln!("wrote {} ({} chunks)", path.display(), chunks);
    }
    Ok(())
}
