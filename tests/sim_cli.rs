//! `leman simulate` end to end: the binary runs an example character and prints the documented
//! JSON object (docs/simulate.md); bad arguments fail with a message naming them.

use std::process::Command;

fn leman() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_leman"));
    c.current_dir(env!("CARGO_MANIFEST_DIR"));
    c
}

/// Runs `leman simulate ARGS`, which must succeed, and returns its standard output.
fn simulate(args: &[&str]) -> String {
    let out = leman().arg("simulate").args(args).output().expect("runs");
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Runs `leman simulate ARGS --json` and returns the one JSON object it prints.
fn simulate_json(args: &[&str]) -> serde_json::Value {
    let mut all = args.to_vec();
    all.push("--json");
    serde_json::from_str(&simulate(&all)).expect("one JSON object")
}

#[test]
fn simulate_prints_the_documented_json() {
    let v = simulate_json(&["arm_16", "--seconds", "0.3", "--integrator", "verlet"]);
    for key in [
        "sim_seconds",
        "wall_seconds",
        "slowdown",
        "steps",
        "rejected_steps",
        "max_penetration_m",
        "epsilon_c_m",
        "nonfinite_events",
        "skin_points",
        "pushed_points_per_step",
        "constraint_phases",
        "recheck_passes_per_phase",
        "rechecked_points_per_phase",
        "unsettled_phases",
        "broadphase_rebuilds",
        "recheck_fraction",
        "held_points_per_step",
        "point_steps_per_second",
    ] {
        assert!(v[key].is_number(), "{key} missing in {v}");
    }
    assert_eq!(v["hold_contacts"], true, "the default");
    // The machine the times were measured on: the vector code that ran, and the CPU's name
    // where Linux gives it.
    let simd = v["machine"]["simd"].as_str().expect("a string");
    assert!(["baseline", "avx2+fma", "avx512"].contains(&simd), "{v}");
    match std::fs::read_to_string("/proc/cpuinfo") {
        Ok(info) if info.contains("model name") => {
            let cpu = v["machine"]["cpu"].as_str().expect("named on Linux");
            assert!(!cpu.is_empty() && info.contains(cpu), "{cpu:?}");
        }
        _ => assert!(v["machine"]["cpu"].is_null(), "{v}"),
    }
    assert!(
        v["interrupted_at_s"].is_null(),
        "not stopped by Ctrl-C: {v}"
    );
    assert!((v["sim_seconds"].as_f64().expect("number") - 0.3).abs() < 1e-6);
    assert_eq!(v["skin_points"], 256);
    // The arm's ε_c, from its file, to read `max_penetration_m` against.
    assert!((v["epsilon_c_m"].as_f64().expect("number") - 0.005).abs() < 1e-9);
    assert!(v["steps"].as_u64().expect("number") > 10);
    assert_eq!(v["nonfinite_events"], 0);
    let min = v["step_secs"]["min"].as_f64().expect("number");
    let max = v["step_secs"]["max"].as_f64().expect("number");
    assert!(0.0 < min && min <= max, "{min} {max}");
    // The arm's skin rests on its bones: some, never more than the free points, are pushed.
    let pushed = v["pushed_points_per_step"].as_f64().expect("number");
    assert!(0.0 < pushed && pushed <= 224.0, "{pushed}");
    // One constraint phase per accepted step or constraint rejection, at most 8 re-check
    // passes each, and each pass over at most the free points.
    let phases = v["constraint_phases"].as_f64().expect("number");
    let steps = v["steps"].as_f64().expect("number");
    let by_constraints = v["constraint_rejections"].as_f64().expect("number");
    assert_eq!(phases, steps + by_constraints);
    let passes = v["recheck_passes_per_phase"].as_f64().expect("number");
    let points = v["rechecked_points_per_phase"].as_f64().expect("number");
    assert!((0.0..=8.0).contains(&passes), "{passes}");
    assert!(v["unsettled_phases"].as_f64().expect("number") <= phases);
    assert!(
        passes <= points && points <= 224.0 * passes,
        "{points} {passes}"
    );
    let f = &v["phase_fraction"];
    let sum = ["force", "constraints", "other"]
        .iter()
        .map(|k| f[k].as_f64().expect("number"))
        .sum::<f64>();
    assert!((sum - 1.0).abs() < 1e-6, "{f}");
    let pps = v["point_steps_per_second"].as_f64().expect("number");
    let expect =
        256.0 * v["steps"].as_f64().expect("number") / v["wall_seconds"].as_f64().expect("number");
    assert!((pps / expect - 1.0).abs() < 1e-9);
}

#[test]
fn simulate_repeat_reports_the_median_run_of_identical_runs() {
    let args = ["arm_16", "--seconds", "0.2"];
    let once = simulate_json(&args);
    let mut repeated = args.to_vec();
    repeated.extend(["--repeat", "3"]);
    let v = simulate_json(&repeated);
    assert_eq!(v["repeats"], 3);
    assert_eq!(once["repeats"], 1);
    // The runs are the same simulation: the same steps as a single run.
    for key in [
        "steps",
        "rejected_steps",
        "force_evals",
        "max_penetration_m",
    ] {
        assert_eq!(v[key], once[key], "{key}");
    }
    let wall = |k: &str| v[k].as_f64().expect("number");
    let (lo, mid, hi) = (
        wall("wall_seconds_min"),
        wall("wall_seconds"),
        wall("wall_seconds_max"),
    );
    assert!(0.0 < lo && lo <= mid && mid <= hi, "{lo} {mid} {hi}");
    assert!((wall("slowdown") - mid / wall("sim_seconds")).abs() < 1e-12);
    let text = simulate(&repeated);
    assert!(text.contains("median of 3 runs"), "{text}");
    // The depth samples of repeated runs are checked to agree, and are those of one run.
    repeated.push("--sample-depth");
    let mut sampled = args.to_vec();
    sampled.push("--sample-depth");
    assert_eq!(
        simulate_json(&repeated)["sampled_depth_m"],
        simulate_json(&sampled)["sampled_depth_m"]
    );
}

#[test]
fn simulate_table_and_resolution_and_every_integrator() {
    for integrator in ["euler", "rk2", "rk4"] {
        let text = simulate(&["penguin_16", "--seconds", "0.1", "--integrator", integrator]);
        assert!(
            text.contains("Timestep interval (ms)")
                && text.contains("% Constraints")
                && text.contains("Points pushed out")
                && text.contains(" vector code)"),
            "{text}"
        );
        assert!(text.contains(integrator));
    }
    let v = simulate_json(&["penguin_16", "--seconds", "0.05", "--resolution", "12x10"]);
    assert_eq!(v["skin_points"], 120);
}

/// `--recheck-fraction` overrides the character's re-check threshold: the report says which
/// was used, and a larger one re-tests fewer points in the same motion.
#[test]
fn simulate_recheck_fraction_sets_the_threshold() {
    let args = ["torso_16", "--seconds", "0.5"];
    let default = simulate_json(&args);
    assert_eq!(default["recheck_fraction"].as_f64(), Some(0.1));
    let mut coarse = args.to_vec();
    coarse.extend(["--recheck-fraction", "0.5"]);
    let v = simulate_json(&coarse);
    assert_eq!(v["recheck_fraction"].as_f64(), Some(0.5));
    let points = |v: &serde_json::Value| {
        v["rechecked_points_per_phase"].as_f64().expect("number")
            * v["constraint_phases"].as_f64().expect("number")
    };
    assert!(
        points(&v) < points(&default),
        "{} re-checked points at 0.5 ε_c, {} at 0.1 ε_c",
        points(&v),
        points(&default)
    );
    let text = simulate(&coarse);
    assert!(text.contains("above 0.5 ε_c"), "{text}");
}

/// `--sample-depth` reports the deepest fat point after every slice: ordered percentiles, the
/// largest within ε_c (5 mm) and at least the final state's; without it the field is null.
#[test]
fn simulate_sample_depth_summarises_the_residual_depths() {
    let args = ["penguin_16", "--seconds", "0.5"];
    assert!(simulate_json(&args)["sampled_depth_m"].is_null());
    let mut sampled = args.to_vec();
    sampled.push("--sample-depth");
    let v = simulate_json(&sampled);
    let d = &v["sampled_depth_m"];
    let get = |k: &str| d[k].as_f64().expect("number");
    let (median, p90, max) = (get("median"), get("p90"), get("max"));
    assert!(0.0 <= median && median <= p90 && p90 <= max, "{d}");
    assert!(max < 0.005, "{d}");
    // The last sample is the final state.
    assert!(
        max >= v["final_max_depth_m"].as_f64().expect("number"),
        "{v}"
    );
    let text = simulate(&sampled);
    assert!(text.contains("Deepest fat point"), "{text}");
}

#[test]
fn simulate_bad_arguments_say_what_is_wrong() {
    for (args, needle) in [
        (vec!["simulate", "no_such_character"], "no_such_character"),
        (
            vec!["simulate", "arm_16", "--resolution", "12by3"],
            "--resolution",
        ),
        (
            vec!["simulate", "arm_16", "--integrator", "leapfrog"],
            "--integrator",
        ),
        (vec!["simulate", "arm_16", "--motion", "dance"], "dance"),
        (vec!["simulate", "arm_16", "--seconds", "0"], "--seconds"),
        (
            // Within the time resolution: nothing would be simulated.
            vec!["simulate", "arm_16", "--seconds", "1e-9"],
            "--seconds 0.000000001: must be a finite number of seconds longer than the \
             simulation's time resolution (0.000000001 s)",
        ),
        (
            vec!["simulate", "arm_16", "--seconds", "-1"],
            "--seconds -1: must be a finite number of seconds",
        ),
        (
            vec!["simulate", "arm_16", "--seconds", "inf"],
            "--seconds inf: must be a finite number of seconds",
        ),
        (vec!["simulate", "arm_16", "--repeat", "0"], "--repeat"),
        (
            vec!["simulate", "arm_16", "--recheck-fraction", "2"],
            "--recheck-fraction 2: must be in (0, 1]",
        ),
    ] {
        let out = leman().args(&args).output().expect("runs");
        assert!(!out.status.success(), "{args:?} should fail");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(needle), "{args:?}: {err}");
    }
}

/// Runs a short `leman simulate` whose reader is gone before the report is written (as in
/// `leman simulate … | head -0`), with `envs` set; returns its exit code and standard error.
/// The pipe's reading end is closed before the child starts, so the write fails every time
/// (closing it after the spawn raced the child's write when the machine was busy).
fn simulate_into_a_closed_pipe(envs: &[(&str, &str)]) -> (Option<i32>, String) {
    let (reader, writer) = std::io::pipe().expect("a pipe");
    drop(reader);
    let out = leman()
        .envs(envs.iter().copied())
        .args([
            "simulate",
            "assets/characters/penguin_16.toml",
            "--seconds",
            "0.05",
        ])
        .stdout(writer)
        .output()
        .expect("leman runs");
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    (out.status.code(), stderr)
}

#[test]
fn simulate_into_a_closed_pipe_reports_an_error_instead_of_panicking() {
    let (code, stderr) = simulate_into_a_closed_pipe(&[]);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(code, Some(1), "{stderr}");
    assert!(stderr.contains("writing the report"), "{stderr}");
}

#[test]
fn errors_print_their_message_and_causes_without_a_stack_trace() {
    // `RUST_BACKTRACE=1` is common on developers' machines; a user-facing error stays a
    // message (and its causes), exit status 1.
    let (code, stderr) =
        simulate_into_a_closed_pipe(&[("RUST_BACKTRACE", "1"), ("RUST_LIB_BACKTRACE", "1")]);
    assert_eq!(code, Some(1), "{stderr}");
    let lines: Vec<&str> = stderr.lines().collect();
    assert_eq!(
        lines.first(),
        Some(&"Error: writing the report to standard output"),
        "{stderr}"
    );
    assert!(lines.contains(&"Caused by:"), "{stderr}");
    assert!(
        !stderr.to_lowercase().contains("backtrace") && !stderr.contains("main.rs"),
        "{stderr}"
    );

    let out = leman()
        .env("RUST_BACKTRACE", "1")
        .args(["simulate", "no_such_character"])
        .output()
        .expect("runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert_eq!(stderr.lines().count(), 1, "one line: {stderr}");
}

#[test]
fn simulate_a_directory_says_it_cannot_read_it_and_names_the_cause_once() {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/assets/characters");
    let out = leman().args(["simulate", dir]).output().expect("runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    let first = stderr.lines().next().unwrap_or_default();
    assert!(
        first.starts_with(&format!("Error: cannot read character file {dir}: ")),
        "{stderr}"
    );
    // The OS's reason ends the message; it is not repeated as a cause below it.
    assert_eq!(stderr.lines().count(), 1, "one line: {stderr}");
}

#[cfg(target_os = "linux")]
#[test]
fn simulate_reads_a_character_piped_to_dev_stdin() {
    let file = std::fs::File::open(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/assets/characters/penguin_16.toml"
    ))
    .expect("the example file");
    let out = leman()
        .args(["simulate", "/dev/stdin", "--seconds", "0.05", "--json"])
        .stdin(file)
        .output()
        .expect("runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    assert_eq!(report["skin_points"], 256, "{report}");
    assert_eq!(report["character"], "penguin", "{report}");
}

#[test]
fn simulate_motion_none_holds_the_neutral_posture() {
    // As `--help` says: `--motion none` runs without a motion (the JSON's motion is null).
    let v = simulate_json(&["penguin_16", "--motion", "none", "--seconds", "0.1"]);
    assert!(v["motion"].is_null(), "{v}");
    assert!((v["sim_seconds"].as_f64().expect("number") - 0.1).abs() < 1e-6);
}

/// `--resolution` finer than the file shortens explicit Euler's step by the square of the
/// spacing (`Character::with_resolution`), and the simulator takes it even below `min_step_s`:
/// the 32×32 penguin at 64×64 on the file's 0.15 ms stalled 0.63 s into its motion.
#[test]
fn a_finer_resolution_steps_euler_short_enough_to_stay_finite() {
    let v = simulate_json(&[
        "penguin",
        "--resolution",
        "64x64",
        "--seconds",
        "0.7",
        "--integrator",
        "euler",
    ]);
    assert!(v["stalled_at_s"].is_null(), "{v}");
    assert_eq!(v["nonfinite_events"], 0, "{v}");
    assert_eq!(v["skin_points"], 64 * 64, "{v}");
    let longest = v["step_secs"]["max"].as_f64().expect("a number");
    assert!(
        (longest - 0.000_15 / 4.0).abs() < 1e-7,
        "a quarter of the file's 0.15 ms: {v}"
    );
}

#[test]
fn simulate_a_character_whose_forces_explode_reports_the_stall_and_fails() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("penguin_far_muscles.toml");
    let source =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/characters/penguin_16.toml");
    let mut c = leman::character::Character::load(&source).expect("example loads");
    // Every tissue spring stretched by a kilometre: no step size survives the guard.
    for s in &mut c.shapes {
        s.joint_from_shape.position_m.y -= 1000.0;
    }
    c.save(&path).expect("saved");
    for json in [false, true] {
        let mut cmd = leman();
        cmd.args([
            "simulate",
            path.to_str().expect("utf-8 path"),
            "--seconds",
            "0.2",
        ]);
        if json {
            cmd.arg("--json");
        }
        let out = cmd.output().expect("runs");
        let (stdout, stderr) = (
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr),
        );
        assert_eq!(out.status.code(), Some(1), "{stdout}\n{stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
        assert!(
            stderr.contains("the simulation stalled at t = 0.0000 s of 0.2 s"),
            "{stderr}"
        );
        assert!(
            !stderr.contains("euler_step_s"),
            "an adaptive run's stall does not blame a fixed step: {stderr}"
        );
        // The report is still printed, and says where it stopped.
        if json {
            let v: serde_json::Value = serde_json::from_str(&stdout).expect("one JSON object");
            assert_eq!(v["stalled_at_s"], 0.0, "{v}");
            assert_eq!(v["steps"], 0, "{v}");
            assert_eq!(v["nonfinite_events"], 8, "{v}");
        } else {
            assert!(stdout.contains("Stalled"), "{stdout}");
            assert!(
                stdout.contains("Simulation slowdown         – (nothing was simulated)"),
                "{stdout}"
            );
        }
    }
    // With a fixed-step integrator the message also names the step as a suspect.
    let out = leman()
        .args([
            "simulate",
            path.to_str().expect("utf-8 path"),
            "--seconds",
            "0.2",
        ])
        .args(["--integrator", "euler"])
        .output()
        .expect("runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("stalled") && stderr.contains("a smaller euler_step_s"),
        "{stderr}"
    );
    // A run that reaches its end reports no stall.
    let v = simulate_json(&["penguin_16", "--seconds", "0.1"]);
    assert!(v["stalled_at_s"].is_null(), "{v}");
}

/// `--hold-contacts false` is the paper's projection alone: the report says so, nothing is
/// held, and the resting skin is pushed out far more often than when its muscles hold it.
#[test]
fn simulate_hold_contacts_switches_the_resting_contact() {
    let args = ["torso_16", "--seconds", "0.5", "--motion", "none"];
    let held = simulate_json(&args);
    let mut off = args.to_vec();
    off.extend(["--hold-contacts", "false"]);
    let projected = simulate_json(&off);
    assert_eq!(held["hold_contacts"], true);
    assert_eq!(projected["hold_contacts"], false);
    let per_step = |v: &serde_json::Value, key: &str| v[key].as_f64().expect("number");
    assert_eq!(per_step(&projected, "held_points_per_step"), 0.0);
    assert!(per_step(&held, "held_points_per_step") > 50.0, "{held}");
    assert!(
        per_step(&held, "pushed_points_per_step")
            < 0.5 * per_step(&projected, "pushed_points_per_step"),
        "held {held}\nprojected {projected}"
    );
    let out = leman()
        .args([
            "simulate",
            "torso_16",
            "--seconds",
            "0.1",
            "--hold-contacts",
            "maybe",
        ])
        .output()
        .expect("runs");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--hold-contacts"), "{err}");
}

/// `--free-steps` lets the steps run past the 1/30 s slice ends: the report says so, the run
/// still covers exactly `--seconds`, and it takes fewer steps than landing on every slice (at
/// least three a slice with the examples' 16 ms cap).
#[test]
fn simulate_free_steps_do_not_land_on_the_slices() {
    let args = ["penguin_16", "--seconds", "1"];
    let landed = simulate_json(&args);
    let mut free_args = args.to_vec();
    free_args.push("--free-steps");
    let free = simulate_json(&free_args);
    assert_eq!(landed["free_steps"], false);
    assert_eq!(free["free_steps"], true);
    let number = |v: &serde_json::Value, key: &str| v[key].as_f64().expect("number");
    assert_eq!(number(&free, "sim_seconds"), 1.0, "{free}");
    assert!(number(&landed, "steps") >= 90.0, "{landed}");
    assert!(
        number(&free, "steps") < number(&landed, "steps"),
        "free {free}\nlanded {landed}"
    );
    let table = simulate(&free_args);
    assert!(table.contains("Step sequence"), "{table}");
    assert!(!simulate(&args).contains("Step sequence"));
}

/// Starts `leman simulate ARGS --json`, sends it SIGINT (as Ctrl-C does) after `after`, and
/// returns its exit code, standard output and standard error.
fn simulate_interrupted(
    args: &[&str],
    after: std::time::Duration,
) -> (Option<i32>, String, String) {
    let child = leman()
        .arg("simulate")
        .args(args)
        .arg("--json")
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("leman starts");
    std::thread::sleep(after);
    let kill = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(kill.success(), "kill -INT failed");
    let out = child.wait_with_output().expect("leman ends");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Ctrl-C during a long run ends it at the next step: the report of the simulated part is
/// still printed, and the exit status is the shell's 130 for SIGINT.
#[test]
fn simulate_stopped_by_ctrl_c_reports_what_it_simulated() {
    // Two seconds: long past loading the character (milliseconds), far short of 10⁶ s.
    let after = std::time::Duration::from_secs(2);
    let (code, stdout, stderr) =
        simulate_interrupted(&["penguin_16", "--seconds", "1000000"], after);
    assert_eq!(code, Some(130), "{stdout}\n{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(stderr.contains("interrupted by Ctrl-C at t = "), "{stderr}");
    assert!(stderr.contains("of 1000000 s"), "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).expect("one JSON object");
    let at = v["interrupted_at_s"].as_f64().expect("a number");
    assert!(at > 0.0 && at < 1e6, "{v}");
    assert_eq!(v["sim_seconds"].as_f64(), Some(at), "{v}");
    assert!(v["steps"].as_u64().expect("number") > 0, "{v}");
    assert!(v["stalled_at_s"].is_null(), "{v}");
    assert_eq!(v["repeats"], 1, "{v}");

    // With --repeat, the runs completed before the press are reported, the cut one is not.
    let (code, stdout, stderr) = simulate_interrupted(
        &["penguin_16", "--seconds", "0.05", "--repeat", "1000000"],
        after,
    );
    assert_eq!(code, Some(130), "{stdout}\n{stderr}");
    assert!(
        stderr.contains("of --repeat 1000000; the report is of the "),
        "{stderr}"
    );
    let v: serde_json::Value = serde_json::from_str(&stdout).expect("one JSON object");
    assert!(v["interrupted_at_s"].is_null(), "{v}");
    assert!(
        (v["sim_seconds"].as_f64().expect("number") - 0.05).abs() < 1e-9,
        "{v}"
    );
    let repeats = v["repeats"].as_u64().expect("number");
    assert!((1..1_000_000).contains(&repeats), "{v}");
    assert!(
        stderr.contains(&format!("the {repeats} complete run")),
        "{stderr}"
    );
}

/// The wombat's motion lasts 2.4 s as its file writes it, an f32 that widens to 2.40000009537
/// s: the run simulates and reports 2.4 s, not 95 ns more.
#[test]
fn simulate_runs_a_motion_for_its_length_as_written() {
    let v = simulate_json(&["wombat_16"]);
    assert_eq!(v["sim_seconds"].as_f64(), Some(2.4), "{v}");
}

/// A run just over the time resolution still takes its step.
#[test]
fn simulate_runs_the_shortest_length_it_accepts() {
    let v = simulate_json(&["arm_16", "--seconds", "2e-9"]);
    assert_eq!(v["sim_seconds"].as_f64(), Some(2e-9), "{v}");
    assert_eq!(v["steps"], 1, "{v}");
}

/// Played from t = 0, a clamped motion whose keys start after 0 runs to its last key (the
/// keys' span alone would stop it short of that key), and a looping one for one period.
#[test]
fn simulate_runs_a_motion_that_starts_late_to_its_last_key() {
    let dir = tempfile::tempdir().expect("temp dir");
    let source =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/characters/wombat_16.toml");
    let mut c = leman::character::Character::load(&source).expect("example loads");
    let motion = &mut c.motions[0];
    for key in &mut motion.keys {
        // Through the written decimals, so that the file says 0.3, …, 2.7.
        key.time_s = (leman::decimal::widen_as_written(key.time_s) + 0.3) as f32;
    }
    for (extrapolation, seconds) in [
        (leman::character::Extrapolation::Clamp, 2.7),
        (leman::character::Extrapolation::Loop, 2.4),
    ] {
        c.motions[0].extrapolation = extrapolation;
        let path = dir
            .path()
            .join(format!("wombat_late_{extrapolation:?}.toml"));
        c.save(&path).expect("saved");
        let v = simulate_json(&[path.to_str().expect("utf-8 path")]);
        assert_eq!(
            v["sim_seconds"].as_f64(),
            Some(seconds),
            "{extrapolation:?}: {v}"
        );
    }
}

/// 0.1005 s is three 1/30 s slices and half a millisecond: the remainder joins the last slice
/// instead of ending the run with a sliver step (which would also be the smallest step).
#[test]
fn simulate_ends_without_a_sliver_step() {
    let v = simulate_json(&["wombat_16", "--seconds", "0.1005"]);
    assert_eq!(v["sim_seconds"].as_f64(), Some(0.1005), "{v}");
    let min = v["step_secs"]["min"].as_f64().expect("number");
    assert!(min > 1e-3, "a sliver step of {min} s: {v}");
}

/// Each fixed-step integrator at each full-resolution example's own step (`euler_step_s`,
/// `rk4_step_s`) stays finite through several seconds of its motion. Explicit Euler grows any
/// mode whose `h ω²` outruns its damping, slowly: the arm at the 0.5 ms of the other examples
/// diverged and stalled after 4.7 s. RK4 at the examples' 2 ms ran 30 s of each by hand (and 4 ms
/// did too); this keeps a character edit from breaking that unnoticed.
#[test]
fn each_fixed_step_method_at_each_examples_own_step_runs_its_motion_without_diverging() {
    for integrator in ["euler", "rk4"] {
        for name in ["penguin", "wombat", "torso", "arm"] {
            let v = simulate_json(&[name, "--integrator", integrator, "--seconds", "6"]);
            let what = format!("{name} with {integrator}: {v}");
            assert!(v["stalled_at_s"].is_null(), "{what}");
            assert_eq!(v["nonfinite_events"], 0, "{what}");
            assert_eq!(v["sim_seconds"].as_f64(), Some(6.0), "{what}");
        }
    }
}
