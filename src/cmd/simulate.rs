//! `leman simulate`: runs a character's elastic surface simulation headless and prints a
//! Table-1 style report (LEMAN paper, section 7), or one JSON object with `--json`
//! (shape documented in docs/simulate.md).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::{Context, bail};
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;

use leman::character::{Character, Primitive};
use leman::clock::{Clock, RealClock};
use leman::sim::surface::SurfaceModel;
use leman::sim::{
    AdvanceEnd, AdvanceReport, DeformationModel, FixedPosture, IntegratorKind, MotionPoses,
    PoseSource, TIME_RESOLUTION_S,
};

/// Arguments of `leman simulate`.
#[derive(Debug, Default, clap::Args)]
pub struct Args {
    /// Character file (TOML), or an example name (`penguin`, `wombat`, `torso`, `arm`, or
    /// `torso_16` for the 16×16 version) looked up in assets/characters/.
    pub character: String,
    /// Motion to play (default: the character's first motion; `none`: hold the neutral
    /// posture, unless the character has a motion of that name).
    #[arg(long)]
    pub motion: Option<String>,
    /// Simulated seconds (default: one pass of the motion from t = 0, at least 2 s: to its last
    /// key, or one period of a looping motion).
    // A negative value is a value, which `run` refuses by name, not an unknown flag.
    #[arg(long, allow_negative_numbers = true)]
    pub seconds: Option<f64>,
    /// Integrator: euler, verlet, rk2 or rk4.
    #[arg(long, default_value = "verlet")]
    pub integrator: String,
    /// Skin resolution `MxN` (around × along), resampled from the file's skin.
    #[arg(long)]
    pub resolution: Option<String>,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Run the simulation this many times, each from the character's initial state, and
    /// report the median run's wall time (for an even count, the slower of the two middle
    /// runs) with the fastest and slowest. Every run must take the same steps (and, with
    /// `--sample-depth`, leave the same depths).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    pub repeat: u32,
    /// Re-check threshold as a fraction of ε_c, in (0, 1] (default: the character's
    /// `recheck_fraction`): larger is faster and leaves fat points deeper.
    #[arg(long)]
    pub recheck_fraction: Option<f32>,
    /// Whether muscles hold the skin resting on them between steps, `true` or `false`
    /// (default: the character's `hold_contacts`, true unless the file says otherwise);
    /// `false` is the paper's projection alone.
    #[arg(long, value_name = "BOOL", action = clap::ArgAction::Set)]
    pub hold_contacts: Option<bool>,
    /// After every 1/30 s slice, find the deepest fat point inside any muscle (brute force, not
    /// timed) and report their median, 90th percentile and largest. The checks run between
    /// the timed slices but evict the simulation's data from the caches, so wall times with
    /// this option are slower than without.
    #[arg(long)]
    pub sample_depth: bool,
    /// Let steps run past the 1/30 s slice ends instead of landing on each (the default, as
    /// every documented figure was measured): the integrator's own step sequence, as the
    /// workstation steps, for comparing integrators or simulators. The run still ends exactly
    /// at `--seconds`.
    #[arg(long)]
    pub free_steps: bool,
}

/// Smallest and largest accepted step, seconds.
#[derive(Debug, Serialize)]
struct StepSecs {
    min: f64,
    max: f64,
}

/// The deepest fat point's depth inside a muscle, sampled after every 1/30 s slice, metres.
#[derive(Debug, Serialize)]
struct DepthSummary {
    median: f32,
    p90: f32,
    max: f32,
}

/// Fractions of the simulation's wall time.
#[derive(Debug, Serialize)]
struct PhaseFraction {
    force: f64,
    constraints: f64,
    other: f64,
}

/// The `--json` object (see docs/simulate.md).
#[derive(Debug, Serialize)]
struct Report {
    character: String,
    file: Option<String>,
    motion: Option<String>,
    integrator: &'static str,
    /// What ran it: wall times and point-steps per second are only comparable on one machine.
    machine: Machine,
    resolution: [u32; 2],
    skin_points: usize,
    muscles: MuscleCounts,
    sim_seconds: f64,
    /// The median run's wall time (of `repeats`).
    wall_seconds: f64,
    /// Runs made, and the fastest and slowest of their wall times.
    repeats: u32,
    wall_seconds_min: f64,
    wall_seconds_max: f64,
    /// `wall_seconds / sim_seconds`; none (null) when nothing was simulated.
    slowdown: Option<f64>,
    steps: u64,
    rejected_steps: u64,
    constraint_rejections: u64,
    forced_steps: u64,
    step_secs: StepSecs,
    force_evals: u64,
    velocity_evals: u64,
    phase_fraction: PhaseFraction,
    max_penetration_m: f32,
    /// ε_c, metres: the largest correction of a position component before a step is rejected
    /// (what `max_penetration_m` is read against).
    epsilon_c_m: f32,
    final_max_depth_m: f32,
    /// The deepest fat point after each 1/30 s slice (brute force, not timed), with
    /// `--sample-depth`.
    sampled_depth_m: Option<DepthSummary>,
    /// Mean skin points the constraint phase pushed out per accepted step.
    pushed_points_per_step: f64,
    /// Mean skin points their muscles held per accepted step.
    held_points_per_step: f64,
    /// Re-check threshold used, as a fraction of ε_c.
    recheck_fraction: f32,
    /// Whether muscles held the skin resting on them.
    hold_contacts: bool,
    /// Whether steps ran past the slice ends (`--free-steps`) instead of landing on them.
    free_steps: bool,
    /// Constraint phases run (accepted steps and constraint rejections).
    constraint_phases: u64,
    /// Mean re-check passes per constraint phase.
    recheck_passes_per_phase: f64,
    /// Mean skin points the re-check passes tested per constraint phase.
    rechecked_points_per_phase: f64,
    /// Constraint phases whose re-checks stopped at their limit still correcting.
    unsettled_phases: u64,
    /// Rebuilds of the constraint broadphase's candidate runs.
    broadphase_rebuilds: u64,
    nonfinite_events: u64,
    /// Simulated time at which the guard gave up (every attempt non-finite or exploding),
    /// seconds; `None` when the run reached its end.
    stalled_at_s: Option<f64>,
    /// Simulated time at which Ctrl-C stopped the reported run, seconds; `None` when it was
    /// not interrupted.
    interrupted_at_s: Option<f64>,
    point_steps_per_second: f64,
}

/// The machine a report's times were measured on.
#[derive(Debug, Serialize)]
struct Machine {
    /// The CPU's model name (Linux's `/proc/cpuinfo`); none (null) where it cannot be read.
    cpu: Option<String>,
    /// The vector instructions the simulation's hot loops run with
    /// ([`leman::sim::simd::SimdLevel::name`]).
    simd: &'static str,
}

impl Machine {
    fn this_one() -> Self {
        let cpu = std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|info| {
                info.lines()
                    .filter_map(|line| line.split_once(':'))
                    .find(|(key, _)| key.trim() == "model name")
                    .map(|(_, value)| value.trim().to_string())
                    .filter(|name| !name.is_empty())
            });
        Machine {
            cpu,
            simd: leman::sim::simd::simd_level().name(),
        }
    }
}

#[derive(Debug, Serialize, Default)]
struct MuscleCounts {
    spheres: usize,
    superellipsoids: usize,
    cylinders: usize,
}

fn resolve_character(arg: &str) -> anyhow::Result<(Character, Option<PathBuf>)> {
    let as_path = Path::new(arg);
    if as_path.exists() {
        // Whatever it is: a directory or a device is read too, and its error says what it is
        // (`/dev/stdin` reads a piped file).
        let c = Character::load(as_path)?;
        return Ok((c, Some(as_path.to_path_buf())));
    }
    let candidates = [
        Path::new("assets/characters").join(format!("{arg}.toml")),
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("assets/characters")
            .join(format!("{arg}.toml")),
    ];
    for path in &candidates {
        if path.is_file() {
            let c = Character::load(path)?;
            return Ok((c, Some(path.clone())));
        }
    }
    // An example name without its file: build it in memory.
    let (name, res) = match arg.strip_suffix("_16") {
        Some(base) => (base, 16),
        None => (arg, 32),
    };
    if let Some(c) = leman::character::examples::build(name, res, res) {
        return Ok((c, None));
    }
    bail!(
        "character {arg:?}: no such file, and not an example name ({})",
        leman::character::examples::NAMES.join(", ")
    )
}

fn parse_resolution(text: &str) -> anyhow::Result<(u32, u32)> {
    let (m, n) = text
        .split_once(['x', 'X', '×'])
        .with_context(|| format!("--resolution {text:?}: expected MxN, e.g. 32x32"))?;
    let m: u32 = m
        .trim()
        .parse()
        .with_context(|| format!("--resolution {text:?}: M is not a number"))?;
    let n: u32 = n
        .trim()
        .parse()
        .with_context(|| format!("--resolution {text:?}: N is not a number"))?;
    Ok((m, n))
}

/// Runs `leman simulate`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let kind = IntegratorKind::from_name(&args.integrator).with_context(|| {
        format!(
            "--integrator {:?}: expected one of euler, verlet, rk2, rk4",
            args.integrator
        )
    })?;
    let (mut character, file) = resolve_character(&args.character)?;
    if let Some(text) = &args.resolution {
        let (m, n) = parse_resolution(text)?;
        character = character
            .with_resolution(m, n)
            .with_context(|| format!("--resolution {text}"))?;
    }
    if let Some(f) = args.recheck_fraction {
        if !leman::character::is_recheck_fraction(f) {
            bail!("--recheck-fraction {f}: must be in (0, 1]");
        }
        character.simulation.recheck_fraction = f;
    }
    if let Some(on) = args.hold_contacts {
        character.simulation.hold_contacts = on;
    }
    let motion = match &args.motion {
        Some(name) if name == "none" && character.motion(name).is_none() => None,
        Some(name) => Some(
            character
                .motion(name)
                .with_context(|| {
                    let names: Vec<_> = character.motions.iter().map(|m| m.name.as_str()).collect();
                    format!(
                        "character {:?} has no motion {name:?} (it has: {})",
                        character.name,
                        names.join(", ")
                    )
                })?
                .clone(),
        ),
        None => character.motions.first().cloned(),
    };
    let seconds = match args.seconds {
        Some(s) if s.is_finite() && s > TIME_RESOLUTION_S => s,
        Some(s) => bail!(
            "--seconds {s}: must be a finite number of seconds longer than the simulation's \
             time resolution ({TIME_RESOLUTION_S} s)"
        ),
        None => motion.as_ref().map(|m| m.pass_s().max(2.0)).unwrap_or(2.0),
    };
    let mut muscles = MuscleCounts::default();
    for s in &character.shapes {
        match s.primitive {
            Primitive::Sphere { .. } => muscles.spheres += 1,
            Primitive::Superellipsoid { .. } => muscles.superellipsoids += 1,
            Primitive::Cylinder { .. } => muscles.cylinders += 1,
        }
    }
    let name = character.name.clone();
    let progress = progress_bar(seconds, args.repeat);
    let stop = stop_on_ctrl_c(&progress)?;
    let mut runs = Vec::with_capacity(args.repeat as usize);
    // The run (counted from 1) that Ctrl-C cut short, if any.
    let mut interrupted_run = None;
    for k in 0..args.repeat {
        if args.repeat > 1 {
            progress.set_message(format!("run {} of {}", k + 1, args.repeat));
        }
        let done_ms = f64::from(k) * seconds * 1000.0;
        let run = run_once(
            character.clone(),
            kind,
            motion.as_ref(),
            RunPlan {
                seconds,
                sample_depth: args.sample_depth,
                free_steps: args.free_steps,
            },
            &stop,
            &|t_s| progress.set_position((done_ms + t_s * 1000.0) as u64),
        )?;
        if run.interrupted {
            interrupted_run = Some(k + 1);
            // A run cut short is reported only when no run is complete: otherwise the report
            // is of the complete runs, which took the same steps.
            if runs.is_empty() {
                runs.push(run);
            }
            break;
        }
        if let Some(first) = runs.first() {
            run.same_as(first)
                .with_context(|| format!("run {} of --repeat {}", k + 1, args.repeat))?;
        }
        runs.push(run);
    }
    progress.finish_and_clear();
    let walls: Vec<Duration> = runs.iter().map(|r| r.wall).collect();
    let run = &runs[median_index(&walls)];
    let (fastest, slowest) = (
        walls.iter().min().copied().unwrap_or_default(),
        walls.iter().max().copied().unwrap_or_default(),
    );
    let (wall, total, model) = (run.wall, &run.total, &run.model);
    let (m, n) = model.resolution();
    let wall_s = wall.as_secs_f64().max(1e-9);
    let sim_s = model.time_s();
    let (force, constraints, other) = total.phases.fractions();
    let rechecks = total.rechecks_per_phase().unwrap_or((0.0, 0.0));
    let report = Report {
        character: name,
        file: file.map(|p| p.display().to_string()),
        motion: motion.map(|m| m.name),
        integrator: kind.name(),
        machine: Machine::this_one(),
        resolution: [m, n],
        skin_points: model.point_count(),
        muscles,
        sim_seconds: sim_s,
        wall_seconds: wall_s,
        repeats: runs.len() as u32,
        wall_seconds_min: fastest.as_secs_f64(),
        wall_seconds_max: slowest.as_secs_f64(),
        slowdown: (sim_s > 0.0).then(|| wall_s / sim_s),
        steps: total.steps,
        rejected_steps: total.rejected_steps,
        constraint_rejections: total.constraint_rejections,
        forced_steps: total.forced_steps,
        step_secs: StepSecs {
            min: if total.steps > 0 {
                total.min_step_s
            } else {
                0.0
            },
            max: total.max_step_s,
        },
        force_evals: total.force_evals,
        velocity_evals: total.velocity_evals,
        phase_fraction: PhaseFraction {
            force,
            constraints,
            other,
        },
        max_penetration_m: total.max_penetration_m,
        epsilon_c_m: model.epsilon_c_m(),
        final_max_depth_m: model.max_depth_m(),
        sampled_depth_m: args.sample_depth.then(|| depth_summary(&run.depths_m)),
        pushed_points_per_step: total.pushed_per_step().unwrap_or(0.0),
        held_points_per_step: total.held_per_step().unwrap_or(0.0),
        recheck_fraction: character.simulation.recheck_fraction,
        hold_contacts: character.simulation.hold_contacts,
        free_steps: args.free_steps,
        constraint_phases: total.constraint_phases,
        recheck_passes_per_phase: rechecks.0,
        rechecked_points_per_phase: rechecks.1,
        unsettled_phases: total.unsettled_phases,
        broadphase_rebuilds: model.broadphase_rebuilds(),
        nonfinite_events: total.nonfinite_events,
        stalled_at_s: (total.end == AdvanceEnd::Stalled).then_some(sim_s),
        interrupted_at_s: run.interrupted.then_some(sim_s),
        point_steps_per_second: model.point_count() as f64 * total.steps as f64 / wall_s,
    };
    // Written, not printed: a closed pipe (`| head`) is an error message, not a panic.
    let mut out = std::io::stdout().lock();
    if args.json {
        writeln!(out, "{}", serde_json::to_string_pretty(&report)?)
    } else {
        print_table(&report, wall, &mut out)
    }
    .context("writing the report to standard output")?;
    if let Some(t) = report.stalled_at_s {
        bail!(
            "the simulation stalled at t = {t:.4} s of {seconds} s: {} attempts in a row, \
             shrinking to the minimum step, were non-finite or exploding, so the last good \
             state was kept ({})",
            leman::sim::surface::GUARD_ATTEMPTS,
            leman::sim::surface::stall_advice(kind)
        );
    }
    if let Some(k) = interrupted_run {
        let what = match report.interrupted_at_s {
            Some(t) => {
                format!("at t = {t:.4} s of {seconds} s; the report is of the simulated part")
            }
            None => format!(
                "in run {k} of --repeat {}; the report is of the {} complete run{}",
                args.repeat,
                report.repeats,
                if report.repeats == 1 { "" } else { "s" }
            ),
        };
        return Err(Interrupted(format!("interrupted by Ctrl-C {what}")).into());
    }
    Ok(())
}

/// A run stopped by Ctrl-C, after its report was printed. `main` exits with status 130, the
/// shell's status for a command ended by SIGINT.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct Interrupted(String);

/// A progress bar on standard error over the simulated milliseconds of all the runs, hidden
/// when standard error is not a terminal. It is moved between the timed slices only.
fn progress_bar(seconds: f64, repeat: u32) -> ProgressBar {
    // `as` saturates: `--seconds 1e300` gives a bar that never fills, not a panic.
    let bar = ProgressBar::new((seconds * 1000.0 * f64::from(repeat)) as u64);
    let style = ProgressStyle::with_template(
        "{msg} [{wide_bar}] {pos}/{len} ms simulated, {elapsed} (Ctrl-C stops and reports)",
    )
    .unwrap_or_else(|_| ProgressStyle::default_bar());
    bar.set_style(style);
    bar
}

/// Installs the Ctrl-C handler: the first press sets the returned flag, which ends the run at
/// its next step (the report of what was simulated is still printed); a second press quits at
/// once with status 130.
fn stop_on_ctrl_c(progress: &ProgressBar) -> anyhow::Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    // A weak handle: the handler outlives the run, and the bar must be dropped (which clears
    // it) when `run` returns, error or not.
    let (flag, progress) = (Arc::clone(&stop), progress.downgrade());
    ctrlc::set_handler(move || {
        if flag.swap(true, Ordering::SeqCst) {
            std::process::exit(130);
        }
        let say = || eprintln!("stopping at the next step (Ctrl-C again to quit at once)");
        match progress.upgrade() {
            Some(bar) => bar.suspend(say),
            None => say(),
        }
    })
    .context("cannot install the Ctrl-C handler")?;
    Ok(stop)
}

/// Index of the median of `walls` (for an even count, the slower of the two middle ones, so
/// the figure reported is always one a run took); 0 when empty.
fn median_index(walls: &[Duration]) -> usize {
    let mut order: Vec<usize> = (0..walls.len()).collect();
    order.sort_by_key(|&i| walls[i]);
    order.get(walls.len() / 2).copied().unwrap_or(0)
}

/// One simulation run and its wall time.
struct Run {
    model: SurfaceModel,
    total: AdvanceReport,
    wall: Duration,
    /// The deepest fat point inside any muscle after each 1/30 s slice, metres.
    depths_m: Vec<f32>,
    /// Whether Ctrl-C ended the run before its last slice.
    interrupted: bool,
}

impl Run {
    /// Whether this run took the same steps as `other` (the simulation is deterministic, so
    /// repeated runs must).
    fn same_as(&self, other: &Run) -> anyhow::Result<()> {
        let (a, b) = (&self.total, &other.total);
        let counts = [
            ("steps", a.steps, b.steps),
            ("rejected_steps", a.rejected_steps, b.rejected_steps),
            ("force_evals", a.force_evals, b.force_evals),
        ];
        for (what, here, first) in counts {
            if here != first {
                bail!("{what} {here}, the first run {first}: the simulation is not deterministic");
            }
        }
        // With --sample-depth the states after every slice must agree too, to the bit.
        let slices = self.depths_m.len().max(other.depths_m.len());
        for k in 0..slices {
            let (here, first) = (self.depths_m.get(k), other.depths_m.get(k));
            if here.map(|d| d.to_bits()) != first.map(|d| d.to_bits()) {
                bail!(
                    "deepest fat point after slice {} is {here:?} m, in the first run {first:?} m: \
                     the simulation is not deterministic",
                    k + 1
                );
            }
        }
        Ok(())
    }
}

/// How one run is paced and what it samples.
#[derive(Debug, Clone, Copy)]
struct RunPlan {
    /// Simulated seconds.
    seconds: f64,
    /// Find the deepest fat point after every slice (`--sample-depth`).
    sample_depth: bool,
    /// Let steps pass the slice ends (`--free-steps`).
    free_steps: bool,
}

/// The shortest last slice `run_once` makes, seconds; a shorter remainder joins the slice before.
const SLIVER_S: f64 = 1e-3;

/// Runs `character` from its initial state through `motion` (the neutral posture if none) for
/// `plan.seconds` of simulated time in 1/30 s slices (frames of a 30 Hz display), landing on
/// each unless `plan.free_steps`, with no wall-clock budget; the wall time is that of the
/// simulation alone. The run ends early, at the next step attempt, once `stop` is set;
/// `progress` is told the simulated time after every slice.
fn run_once(
    character: Character,
    kind: IntegratorKind,
    motion: Option<&leman::character::Motion>,
    plan: RunPlan,
    stop: &AtomicBool,
    progress: &dyn Fn(f64),
) -> anyhow::Result<Run> {
    let neutral = leman::character::Posture::neutral(&character.skeleton);
    let mut model = SurfaceModel::new(character, kind)?;
    let clock = RealClock::new();
    let mut fixed = FixedPosture(neutral);
    let mut motion_poses = motion.map(MotionPoses);
    let poses: &mut dyn PoseSource = match motion_poses.as_mut() {
        Some(p) => p,
        None => &mut fixed,
    };
    let mut total = AdvanceReport::default();
    let mut wall = Duration::ZERO;
    let mut depths_m = Vec::new();
    let slice = 1.0 / 30.0;
    let mut target = 0.0f64;
    let mut until_stopped = || !stop.load(Ordering::Relaxed);
    let mut interrupted = false;
    while target < plan.seconds {
        // A remainder under a millisecond joins this slice instead of becoming a sliver step
        // of its own (`--seconds 0.1005` would end with a 0.5 ms step, which would also show
        // as the smallest step in the report).
        let next = target + slice;
        target = if plan.seconds - next < SLIVER_S {
            plan.seconds
        } else {
            next
        };
        let start = clock.now();
        // Free steps pass a slice's end by up to one step, but never the run's.
        let r = if plan.free_steps {
            model.advance_past(
                target,
                plan.seconds,
                poses,
                &mut until_stopped,
                Some(&clock),
            )
        } else {
            model.advance(target, poses, &mut until_stopped, Some(&clock))
        };
        wall += clock.now().saturating_sub(start);
        total.merge(&r);
        if plan.sample_depth {
            // Outside the timed part: a brute-force check of every point against every shape.
            depths_m.push(model.max_depth_m());
        }
        progress(model.time_s());
        if !r.reached_target() {
            interrupted = r.end == AdvanceEnd::BudgetSpent;
            break;
        }
    }
    Ok(Run {
        model,
        total,
        wall,
        depths_m,
        interrupted,
    })
}

/// Median, 90th percentile and largest of `values` (non-finite ones left out; all 0 when
/// none are left): nearest-rank percentiles of the sorted values.
fn depth_summary(values: &[f32]) -> DepthSummary {
    let mut v: Vec<f32> = values.iter().copied().filter(|d| d.is_finite()).collect();
    v.sort_by(f32::total_cmp);
    let rank = |p: f64| {
        if v.is_empty() {
            0.0
        } else {
            let k = ((p * v.len() as f64).ceil() as usize).clamp(1, v.len());
            v[k - 1]
        }
    };
    DepthSummary {
        median: rank(0.5),
        p90: rank(0.9),
        max: rank(1.0),
    }
}

fn print_table(r: &Report, wall: Duration, out: &mut impl Write) -> std::io::Result<()> {
    let ms = |s: f64| s * 1000.0;
    writeln!(out, "{:<28}{}", "Character", r.character)?;
    writeln!(
        out,
        "{:<28}{} mass points ({}×{})",
        "Skin mesh", r.skin_points, r.resolution[0], r.resolution[1]
    )?;
    let count =
        |n: usize, one: &str, many: &str| format!("{n} {}", if n == 1 { one } else { many });
    writeln!(
        out,
        "{:<28}{}, {}, {}",
        "Muscle layer",
        count(r.muscles.spheres, "sphere", "spheres"),
        count(
            r.muscles.superellipsoids,
            "superellipsoid",
            "superellipsoids"
        ),
        count(r.muscles.cylinders, "cylinder", "cylinders"),
    )?;
    writeln!(
        out,
        "{:<28}{}",
        "Motion",
        r.motion.as_deref().unwrap_or("(neutral posture)")
    )?;
    writeln!(out, "{:<28}{}", "Solver", r.integrator)?;
    writeln!(
        out,
        "{:<28}{} ({} vector code)",
        "Machine",
        r.machine.cpu.as_deref().unwrap_or("unknown CPU"),
        r.machine.simd
    )?;
    writeln!(
        out,
        "{:<28}[{:.2}–{:.2}]",
        "Timestep interval (ms)",
        ms(r.step_secs.min),
        ms(r.step_secs.max)
    )?;
    let speed = match r.slowdown {
        None => "– (nothing was simulated)".to_string(),
        Some(slowdown) if slowdown >= 1.0 => {
            format!("{slowdown:.2}× (slower than real time)")
        }
        Some(slowdown) => format!(
            "{slowdown:.4}× ({:.1}× faster than real time)",
            1.0 / slowdown
        ),
    };
    writeln!(out, "{:<28}{speed}", "Simulation slowdown")?;
    writeln!(
        out,
        "{:<28}{:.1}",
        "% Force evaluation",
        100.0 * r.phase_fraction.force
    )?;
    writeln!(
        out,
        "{:<28}{:.1}",
        "% Constraints",
        100.0 * r.phase_fraction.constraints
    )?;
    writeln!(
        out,
        "{:<28}{:.1}",
        "% Other",
        100.0 * r.phase_fraction.other
    )?;
    writeln!(
        out,
        "{:<28}{} accepted, {} rejected ({} by constraints), {} forced",
        "Steps", r.steps, r.rejected_steps, r.constraint_rejections, r.forced_steps
    )?;
    if r.free_steps {
        writeln!(
            out,
            "{:<28}free (not landed on the 1/30 s slice ends)",
            "Step sequence"
        )?;
    }
    writeln!(
        out,
        "{:<28}{:.3e}",
        "Point-steps per second", r.point_steps_per_second
    )?;
    writeln!(
        out,
        "{:<28}{:.2} mm (final state {:.3} mm; ε_c {:.2} mm per coordinate)",
        "Max penetration",
        r.max_penetration_m * 1000.0,
        r.final_max_depth_m * 1000.0,
        r.epsilon_c_m * 1000.0
    )?;
    if let Some(d) = &r.sampled_depth_m {
        writeln!(
            out,
            "{:<28}{:.3} / {:.3} / {:.3} mm (median / p90 / max, every 1/30 s)",
            "Deepest fat point",
            d.median * 1000.0,
            d.p90 * 1000.0,
            d.max * 1000.0
        )?;
    }
    writeln!(
        out,
        "{:<28}{:.0} of {} per step",
        "Points pushed out", r.pushed_points_per_step, r.skin_points
    )?;
    if r.hold_contacts {
        writeln!(
            out,
            "{:<28}{:.0} of {} per step",
            "Points held on muscles", r.held_points_per_step, r.skin_points
        )?;
    } else {
        writeln!(
            out,
            "{:<28}off (projection alone)",
            "Points held on muscles"
        )?;
    }
    writeln!(
        out,
        "{:<28}{:.2} passes, {:.0} points per constraint phase ({} phases, {} unsettled; above {} ε_c)",
        "Re-checks",
        r.recheck_passes_per_phase,
        r.rechecked_points_per_phase,
        r.constraint_phases,
        r.unsettled_phases,
        r.recheck_fraction
    )?;
    writeln!(
        out,
        "{:<28}{} ({:.1} constraint phases per rebuild)",
        "Broadphase rebuilds",
        r.broadphase_rebuilds,
        r.constraint_phases as f64 / r.broadphase_rebuilds.max(1) as f64
    )?;
    writeln!(out, "{:<28}{}", "Non-finite events", r.nonfinite_events)?;
    if let Some(t) = r.stalled_at_s {
        writeln!(out, "{:<28}at {t:.4} s (the guard gave up)", "Stalled")?;
    }
    if let Some(t) = r.interrupted_at_s {
        writeln!(out, "{:<28}at {t:.4} s (Ctrl-C)", "Interrupted")?;
    }
    write!(
        out,
        "{:<28}{:.3} s simulated in {:.3} s",
        "Time",
        r.sim_seconds,
        wall.as_secs_f64()
    )?;
    if r.repeats > 1 {
        write!(
            out,
            " (median of {} runs, {:.3}–{:.3} s)",
            r.repeats, r.wall_seconds_min, r.wall_seconds_max
        )?;
    }
    writeln!(out)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_median_run_is_the_middle_one_by_wall_time() {
        let ms = Duration::from_millis;
        assert_eq!(median_index(&[ms(30), ms(10), ms(20)]), 2);
        assert_eq!(median_index(&[ms(5)]), 0);
        // Even count: the slower of the two middle runs.
        assert_eq!(median_index(&[ms(40), ms(10), ms(30), ms(20)]), 2);
        assert_eq!(median_index(&[]), 0);
    }
}
