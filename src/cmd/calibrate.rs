//! `leman calibrate`: the corner-touching screen calibration (live or from a recorded session),
//! the same fit from recorded corner samples (`--corners`), or a check of a profile (`--check`).
//! The JSON shapes are documented in docs/calibration.md.

use anyhow::{Context, bail};
use glam::{Mat4, Quat, Vec3};
use leman::calibration::drive::{SnapshotFeeder, run_on_session_with};
use leman::calibration::{
    CalibrationProfile, Corner, CornerProcedure, FitOptions, ProcedureConfig, ProcedureEvent,
    ScreenFit, ScreenRect, Step, Units, fit_screen,
};
use leman::clock::RealClock;
use leman::devices::hub::{Hub, HubOptions};
use leman::devices::profile::{DeviceKind, Profile as DeviceProfile, Role};
use leman::devices::session::Session;
use leman::pose::Pose;
use leman::stereo::{EyeView, ViewSettings, eye_views};
use serde::Deserialize;
use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// Arguments of `leman calibrate`.
#[derive(Debug, Default, clap::Args)]
pub struct Args {
    /// Fit the screen from recorded corner samples in this JSON file
    /// (`{"units": "m"|"cm"|"in", "lower_left": [[x,y,z], ...], "lower_right": [...],
    /// "upper_left": [...], "upper_right": [...]}`, upper_right optional, world frame).
    #[arg(long, value_name = "FILE.json", conflicts_with_all = ["check", "replay"])]
    pub corners: Option<PathBuf>,
    /// Where to write the calibration profile (TOML).
    #[arg(long, value_name = "PROFILE.toml")]
    pub out: Option<PathBuf>,
    /// Print the screen frame and both eyes' projections for a head pose.
    #[arg(long)]
    pub check: bool,
    /// The calibration profile to check, or to start from when fitting (head, tracker and
    /// filter settings are kept); the built-in default desktop profile if absent.
    #[arg(long, value_name = "PROFILE.toml")]
    pub calibration: Option<PathBuf>,
    /// Head sensor pose in the world frame for `--check`: x,y,z (metres),qx,qy,qz,qw (unit
    /// quaternion). Default: the profile's default head pose.
    #[arg(long, value_name = "x,y,z,qx,qy,qz,qw", allow_hyphen_values = true)]
    pub head: Option<String>,
    /// Near clip plane (metres) for `--check`.
    #[arg(long, value_name = "N")]
    pub near: Option<f32>,
    /// Far clip plane (metres) for `--check`.
    #[arg(long, value_name = "F")]
    pub far: Option<f32>,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
    /// Device profile (TOML) with a tracked wand, for the live procedure (required for it:
    /// the desktop mouse has no 3D position). Not with `--replay`: a session holds the profile
    /// it was recorded with.
    #[arg(long, value_name = "DEVICES.toml", conflicts_with = "replay")]
    pub profile: Option<PathBuf>,
    /// Run the procedure on a recorded device session instead of live devices.
    #[arg(long, value_name = "SESSION")]
    pub replay: Option<PathBuf>,
}

/// Runs `leman calibrate`.
pub fn run(args: Args) -> anyhow::Result<()> {
    if args.check {
        return check(&args);
    }
    if let Some(corners) = &args.corners {
        return fit_from_corners(&args, corners);
    }
    interactive(&args)
}

fn base_profile(args: &Args) -> anyhow::Result<CalibrationProfile> {
    Ok(match &args.calibration {
        Some(path) => CalibrationProfile::load(path)?,
        None => CalibrationProfile::default(),
    })
}

/// The corner samples file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CornersFile {
    units: Units,
    lower_left: Vec<[f64; 3]>,
    lower_right: Vec<[f64; 3]>,
    upper_left: Vec<[f64; 3]>,
    #[serde(default)]
    upper_right: Option<Vec<[f64; 3]>>,
}

/// Reads a corners file into metres.
pub fn read_corners(path: &Path) -> anyhow::Result<leman::calibration::fit::CornerSamples> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read corner samples {}", path.display()))?;
    let file: CornersFile = serde_json::from_str(&text)
        .with_context(|| format!("corner samples {}: not the expected JSON", path.display()))?;
    let scale = f64::from(file.units.metres_per_unit());
    let mut out = leman::calibration::fit::CornerSamples::new();
    for (corner, samples) in [
        (Corner::LowerLeft, Some(file.lower_left)),
        (Corner::LowerRight, Some(file.lower_right)),
        (Corner::UpperLeft, Some(file.upper_left)),
        (Corner::UpperRight, file.upper_right),
    ] {
        let Some(samples) = samples else { continue };
        let mut v = Vec::with_capacity(samples.len());
        for (i, p) in samples.iter().enumerate() {
            let m = [p[0] * scale, p[1] * scale, p[2] * scale];
            if !m.iter().all(|x| x.is_finite() && x.abs() < 1e6) {
                bail!(
                    "corner samples {}: {}[{i}] = {p:?} is out of range",
                    path.display(),
                    corner.name()
                );
            }
            v.push(Vec3::new(m[0] as f32, m[1] as f32, m[2] as f32));
        }
        out.insert(corner, v);
    }
    Ok(out)
}

/// An f32 as the JSON number with the same shortest decimal form (`0.265`, not
/// `0.26499998569488525`); `null` if not finite.
fn num(x: f32) -> Value {
    x.to_string()
        .parse::<f64>()
        .ok()
        .and_then(serde_json::Number::from_f64)
        .map_or(Value::Null, Value::Number)
}

fn v3(v: Vec3) -> Value {
    Value::Array(v.to_array().into_iter().map(num).collect())
}

fn m4(m: &Mat4) -> Value {
    Value::Array(m.to_cols_array().into_iter().map(num).collect())
}

fn screen_json(screen: &ScreenRect, residual_m: f32) -> Value {
    json!({
        "lower_left": v3(screen.lower_left_m),
        "lower_right": v3(screen.lower_right_m),
        "upper_left": v3(screen.upper_left_m),
        "width_m": num(screen.width_m()),
        "height_m": num(screen.height_m()),
        "residual_m": num(residual_m),
    })
}

fn fit_json(fit: &ScreenFit, out: Option<&Path>) -> Value {
    json!({
        "screen": screen_json(&fit.screen, fit.residual_m),
        "non_planarity_m": num(fit.non_planarity_m),
        "measured_angle_deg": num(fit.measured_angle_deg),
        "corners": fit.corners.iter().map(|c| json!({
            "corner": c.corner.name(),
            "measured_m": v3(c.measured_m),
            "kept": c.kept,
            "rejected": c.rejected,
            "error_m": num(c.error_m),
        })).collect::<Vec<_>>(),
        "out": out.map(|p| p.display().to_string()),
    })
}

fn print_fit(fit: &ScreenFit, out: Option<&Path>, as_json: bool) -> anyhow::Result<()> {
    if as_json {
        println!("{}", serde_json::to_string_pretty(&fit_json(fit, out))?);
        return Ok(());
    }
    let s = &fit.screen;
    println!(
        "screen {:.4} m x {:.4} m, residual {:.4} m RMS, non-planarity {:.4} m, measured corner angle {:.2} deg",
        s.width_m(),
        s.height_m(),
        fit.residual_m,
        fit.non_planarity_m,
        fit.measured_angle_deg
    );
    for c in &fit.corners {
        println!(
            "  {:<12} kept {:>3}, rejected {:>3}, off the rectangle by {:.4} m",
            c.corner.name(),
            c.kept,
            c.rejected,
            c.error_m
        );
    }
    if let Some(out) = out {
        println!("wrote {}", out.display());
    }
    Ok(())
}

/// Saves `fit` into a profile built on `args.calibration` (or the default) at `args.out`.
fn save_fit(args: &Args, fit: &ScreenFit, name: &str) -> anyhow::Result<()> {
    let mut profile = base_profile(args)?;
    let head_m = profile.default_head.position_m;
    if fit.screen.distance_in_front_m(head_m) <= 0.0 {
        eprintln!(
            "warning: the fitted screen faces away from the profile's default head position {:?}; were the corners touched in mirrored order (left and right swapped)?",
            head_m.to_array()
        );
    }
    profile.screen = fit.screen;
    profile.residual_m = fit.residual_m;
    profile.name = name.to_owned();
    if let Some(out) = &args.out {
        profile.save(out)?;
    }
    print_fit(fit, args.out.as_deref(), args.json)
}

fn fit_from_corners(args: &Args, corners: &Path) -> anyhow::Result<()> {
    if args.out.is_none() && !args.json {
        bail!("--corners needs --out PROFILE.toml (or --json to only print the fit)");
    }
    let samples = read_corners(corners)?;
    let fit = fit_screen(&samples, &FitOptions::default())
        .with_context(|| format!("cannot fit a screen to {}", corners.display()))?;
    save_fit(args, &fit, &format!("fitted from {}", corners.display()))
}

/// Parses `x,y,z,qx,qy,qz,qw`.
pub fn parse_head(text: &str) -> anyhow::Result<Pose> {
    let nums: Vec<f32> = text
        .split(',')
        .map(|s| s.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .with_context(|| format!("--head {text:?}: expected 7 numbers x,y,z,qx,qy,qz,qw"))?;
    let [x, y, z, qx, qy, qz, qw] = nums[..] else {
        bail!(
            "--head {text:?}: expected 7 numbers x,y,z,qx,qy,qz,qw, got {}",
            nums.len()
        );
    };
    let q = Quat::from_xyzw(qx, qy, qz, qw);
    if !(nums.iter().all(|v| v.is_finite())) {
        bail!("--head {text:?}: numbers must be finite");
    }
    if (q.length() - 1.0).abs() > 1e-3 {
        bail!(
            "--head {text:?}: the quaternion has length {}, must be a unit quaternion",
            q.length()
        );
    }
    Ok(Pose::new(Vec3::new(x, y, z), q.normalize()))
}

fn eye_json(v: &EyeView) -> Value {
    json!({
        "position_m": v3(v.position_m),
        "clip_from_world": m4(&v.clip_from_world),
    })
}

fn check(args: &Args) -> anyhow::Result<()> {
    let profile = base_profile(args)?;
    let head = match &args.head {
        Some(text) => parse_head(text)?,
        None => profile.default_head,
    };
    let defaults = ViewSettings::default();
    let settings = ViewSettings {
        near_m: args.near.unwrap_or(defaults.near_m),
        far_m: args.far.unwrap_or(defaults.far_m),
        ..defaults
    };
    let views = eye_views(&profile, &head, &settings)?;
    if views.clamped {
        eprintln!(
            "warning: the eyes are closer than {} m to the screen plane (or behind it); they were moved out",
            settings.min_eye_distance_m
        );
    }
    if args.json {
        let out = json!({
            "screen": screen_json(&profile.screen, profile.residual_m),
            "eyes": {
                "left": eye_json(&views.left),
                "right": eye_json(&views.right),
            },
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    let s = &profile.screen;
    println!(
        "profile {:?}: screen {:.4} m x {:.4} m, residual {:.4} m",
        profile.name,
        s.width_m(),
        s.height_m(),
        profile.residual_m
    );
    println!(
        "  lower_left {:?}, lower_right {:?}, upper_left {:?}, normal {:?}",
        s.lower_left_m.to_array(),
        s.lower_right_m.to_array(),
        s.upper_left_m.to_array(),
        s.normal().to_array()
    );
    for v in [&views.left, &views.right] {
        let f = &v.frustum;
        println!(
            "  {:?} eye at {:?}, {:.4} m from the screen; frustum at near {} m: l {:.5} r {:.5} b {:.5} t {:.5}, far {} m",
            v.eye,
            v.position_m.to_array(),
            v.screen_distance_m,
            f.near_m,
            f.left_m,
            f.right_m,
            f.bottom_m,
            f.top_m,
            f.far_m
        );
    }
    Ok(())
}

fn describe(event: &ProcedureEvent) -> String {
    match event {
        ProcedureEvent::PressIgnoredMoving {
            speed_m_per_s,
            spread_m,
        } => format!(
            "  press ignored: the wand is moving ({speed_m_per_s:.3} m/s, {spread_m:.4} m spread); hold it still"
        ),
        ProcedureEvent::PressIgnoredTooFewSamples { samples } => {
            format!("  press ignored: only {samples} wand samples so far; hold still a moment")
        }
        ProcedureEvent::SampleIgnored => "  a wand sample was not finite (ignored)".to_owned(),
        ProcedureEvent::Recorded {
            corner,
            mean_m,
            samples,
        } => format!(
            "  recorded {} at {:?} m ({samples} samples)",
            corner.name(),
            mean_m.to_array()
        ),
        ProcedureEvent::Accepted => "  accepted".to_owned(),
        ProcedureEvent::Restarted => "  starting again".to_owned(),
    }
}

/// Prints the prompt whenever it changes (text mode only; prompts go to stderr with --json).
struct Narrator {
    last_prompt: String,
    json: bool,
}

impl Narrator {
    fn say(&self, line: &str) {
        if self.json {
            eprintln!("{line}");
        } else {
            println!("{line}");
        }
    }

    fn event(&mut self, procedure: &CornerProcedure, event: Option<&ProcedureEvent>) {
        if let Some(e) = event {
            self.say(&describe(e));
        }
        let prompt = procedure.prompt();
        if prompt != self.last_prompt {
            self.say(&prompt);
            self.last_prompt = prompt;
        }
    }
}

fn finish(args: &Args, procedure: &CornerProcedure, source: &str) -> anyhow::Result<()> {
    match procedure.step() {
        Step::Done(fit) => save_fit(args, fit, &format!("touched corners ({source})")),
        other => bail!(
            "{source}: the procedure did not finish (at: {}); nothing written",
            match other {
                Step::Touch { corner, .. } => format!("waiting for the {} corner", corner.name()),
                Step::Review(Ok(_)) => "review, not accepted".to_owned(),
                Step::Review(Err(e)) => format!("review, the fit failed: {e}"),
                Step::Done(_) => "done".to_owned(),
            }
        ),
    }
}

fn interactive(args: &Args) -> anyhow::Result<()> {
    if args.out.is_none() {
        bail!("the corner procedure needs --out PROFILE.toml");
    }
    let base = base_profile(args)?;
    let mut narrator = Narrator {
        last_prompt: String::new(),
        json: args.json,
    };
    if let Some(path) = &args.replay {
        let session = Session::load(path)?;
        narrator.event(&CornerProcedure::new(ProcedureConfig::default()), None);
        let json = narrator.json;
        let procedure = run_on_session_with(
            session,
            ProcedureConfig::default(),
            &base.tracker,
            |at, e, p| {
                if !json {
                    print!("[{:7.3} s]", at.as_secs_f64());
                }
                narrator.event(p, Some(e));
            },
        )?;
        return finish(args, &procedure, &path.display().to_string());
    }
    live(args, &base, &mut narrator)
}

fn live(args: &Args, base: &CalibrationProfile, narrator: &mut Narrator) -> anyhow::Result<()> {
    let Some(devices) = &args.profile else {
        bail!(
            "live calibration needs a tracked wand: pass --profile DEVICES.toml (e.g. devices/fastrak-spaceball.toml), or --replay SESSION; the desktop mouse has no 3D position"
        );
    };
    let profile = DeviceProfile::load(devices)?;
    let Some(wand) = profile.binding(Role::Wand) else {
        bail!("{}: no device is bound to the wand role", devices.display());
    };
    let wand_device = profile
        .device_index(&wand.device)
        .map(|i| &profile.devices[i]);
    if wand_device.is_some_and(|d| d.protocol == DeviceKind::Desktop) {
        bail!(
            "{}: the wand role is bound to the desktop device {:?}, but the mouse has no 3D \
             position to touch the corners with: bind it to a tracker",
            devices.display(),
            wand.device
        );
    }
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst))
            .context("cannot install the Ctrl-C handler")?;
    }
    let hub = Hub::start(profile, Arc::new(RealClock::new()), HubOptions::default())?;
    let mut procedure = CornerProcedure::new(ProcedureConfig::default());
    let mut feeder = SnapshotFeeder::new();
    narrator.event(&procedure, None);
    let mut last_state = None;
    while !stop.load(Ordering::SeqCst) {
        let snapshot = hub.snapshot();
        let wand = snapshot.role(Role::Wand);
        if last_state != Some(wand.state) {
            narrator.say(&format!("  wand device: {:?}", wand.state));
            last_state = Some(wand.state);
        }
        let event = feeder.feed(&mut procedure, &snapshot, &base.tracker);
        if event.is_some() {
            narrator.event(&procedure, event.as_ref());
        }
        if matches!(procedure.step(), Step::Done(_)) {
            break;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    hub.stop()?;
    if stop.load(Ordering::SeqCst) {
        bail!("cancelled; nothing written");
    }
    finish(args, &procedure, "live devices")
}
