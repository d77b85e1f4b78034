//! `leman record`: records live devices into a session file until Ctrl-C.

use anyhow::Context as _;
use leman::clock::RealClock;
use leman::devices::hub::{DeviceState, Hub, HubOptions};
use leman::devices::profile::{DeviceKind, Profile};
use leman::devices::session::Session;
use std::path::{Path, PathBuf};
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
    #[arg(long, allow_negative_numbers = true, value_parser = seconds_arg)]
    pub seconds: Option<f64>,
    /// Print each device's state and rate every this many seconds (0 = never).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true, value_parser = seconds_arg)]
    pub status_every: f64,
    /// Instead of recording: read a recording that was cut short (the `.NAME.partial` file a
    /// killed `leman record` leaves) or damaged, and write its header and every record before
    /// the first fault to `--out` as a whole session. The file read is left as it is.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["profile", "seconds"])]
    pub recover: Option<PathBuf>,
    /// Replace `--out` if it exists (without this, an existing file is refused before any
    /// device opens, so an earlier recording is never lost to a repeated command).
    #[arg(long)]
    pub overwrite: bool,
}

/// A span of seconds on the command line: finite, not negative and short enough for a
/// `Duration` (a NaN or negative `--seconds` used to be taken as "no limit" and recorded until
/// Ctrl-C; one over about 584 000 years did the same).
fn seconds_arg(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(s) if s.is_finite() && s >= 0.0 && Duration::try_from_secs_f64(s).is_ok() => Ok(s),
        Ok(s) if s.is_finite() && s >= 0.0 => Err(format!("{s} seconds is too long a span")),
        Ok(s) => Err(format!("{s} is not a number of seconds (need 0 or more)")),
        Err(e) => Err(format!("{text:?} is not a number of seconds: {e}")),
    }
}

/// Runs `leman record`.
pub fn run(args: Args) -> anyhow::Result<()> {
    if let Some(from) = &args.recover {
        let out = args
            .out
            .as_deref()
            .context("--out SESSION is required: where to write what --recover keeps")?;
        return recover(from, out, args.overwrite);
    }
    let profile_path = args
        .profile
        .context("--profile FILE is required (see devices/*.toml)")?;
    let out = args.out.context("--out SESSION is required")?;
    super::refuse_existing("--out", &out, args.overwrite)?;
    let profile = Profile::load(&profile_path)?;
    // The desktop stand-ins take their events from the workstation's window; this command
    // opens none, so they would record nothing.
    let desktop: Vec<&str> = profile
        .devices
        .iter()
        .filter(|d| d.protocol == DeviceKind::Desktop)
        .map(|d| d.name.as_str())
        .collect();
    if profile.devices.is_empty() {
        anyhow::bail!(
            "{}: the profile has no devices to record",
            profile_path.display()
        );
    }
    if desktop.len() == profile.devices.len() {
        anyhow::bail!(
            "{}: every device is the desktop mouse and keyboard, which `leman record` cannot \
             record (it opens no window): name a profile with a tracker or a 3D mouse, or \
             record with the workstation open (`leman run --record SESSION`)",
            profile_path.display()
        );
    }
    for name in desktop {
        eprintln!(
            "note: device {name:?} (the desktop mouse and keyboard) records nothing here: \
             `leman record` opens no window (`leman run --record SESSION` does)"
        );
    }
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
    // `seconds_arg` took only spans a `Duration` holds.
    let limit = args
        .seconds
        .and_then(|s| Duration::try_from_secs_f64(s).ok());
    let every = Duration::try_from_secs_f64(args.status_every)
        .ok()
        .filter(|d| !d.is_zero());
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

/// `leman record --recover FROM --out OUT`: writes what can be read of `FROM` to `OUT` (an
/// existing `OUT` only with `overwrite`, and never `FROM` itself).
fn recover(from: &Path, out: &Path, overwrite: bool) -> anyhow::Result<()> {
    let same = |a: &Path, b: &Path| match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    };
    if same(from, out) {
        anyhow::bail!(
            "--out {} is the file being recovered: name a new file, so that the damaged \
             recording stays as it is",
            out.display()
        );
    }
    super::refuse_existing("--out", out, overwrite)?;
    let recovered = Session::recover_file(from)?;
    recovered.session.save(out)?;
    let session = &recovered.session;
    println!(
        "kept {} records ({:.3} s of devices) of {} in {}",
        session.records.len(),
        session.duration().as_secs_f64(),
        from.display(),
        out.display()
    );
    match recovered.dropped {
        None => println!("the file was whole: nothing dropped"),
        Some(d) if d.bytes == 0 => println!("nothing dropped, but {}", d.reason),
        Some(d) => println!("dropped {} bytes: {}", d.bytes, d.reason),
    }
    Ok(())
}
