//! End to end: `leman replay SESSION --headless` plays a recorded FASTRAK session (head and
//! wand) through the whole app — decoders, hub state, vehicle, the torso's surface simulation,
//! stereo, the renderer on lavapipe — and writes PNG frames and the JSON-lines frame log.
//!
//! Without a GPU driver the test prints a loud SKIPPED, unless `LEMAN_REQUIRE_GPU=1`, when it
//! fails.

use leman::render::GpuContext;
use leman::render::RgbaImage;
use leman::render::device_caps::gpu_required_by_env;
use std::path::Path;
use std::process::Command;

fn gpu_available() -> bool {
    match GpuContext::new_headless() {
        Ok(_) => true,
        Err(e) if gpu_required_by_env() => panic!("LEMAN_REQUIRE_GPU=1 but no GPU: {e}"),
        Err(e) => {
            eprintln!("\n*** SKIPPED app_replay: no GPU adapter ({e}). ***\n");
            false
        }
    }
}

/// Pixels that look like the skin (light, warm: red > green > blue).
fn skin_pixels(image: &RgbaImage) -> usize {
    image
        .pixels
        .chunks_exact(4)
        .filter(|p| {
            let (r, g, b) = (i32::from(p[0]), i32::from(p[1]), i32::from(p[2]));
            r > 140 && r > g + 10 && g > b && r - b > 35
        })
        .count()
}

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// A temporary folder (kept while the first value lives) with the path of a `frames` folder
/// in it and a private `XDG_RUNTIME_DIR` for Mesa.
fn scratch() -> (tempfile::TempDir, std::path::PathBuf, std::path::PathBuf) {
    let dir = tempfile::tempdir().expect("tempdir");
    let frames = dir.path().join("frames");
    let runtime = dir.path().join("xdg");
    std::fs::create_dir_all(&runtime).expect("runtime dir");
    (dir, frames, runtime)
}

#[test]
fn headless_replay_of_a_fastrak_session_writes_frames_and_a_frame_log() {
    if !gpu_available() {
        return;
    }
    let (_dir, frames, runtime) = scratch();
    let session = root().join("devices/sessions/fastrak-ascii.session");
    let output = Command::new(env!("CARGO_BIN_EXE_leman"))
        .current_dir(root())
        .env("XDG_RUNTIME_DIR", &runtime)
        .args([
            "replay",
            "--headless",
            "--json",
            "--stereo",
            "sbs",
            "--size",
            "320x180",
        ])
        .args(["--every", "20", "--frame-count", "60", "--frames"])
        .arg(&frames)
        .arg(&session)
        .output()
        .expect("run leman");
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "leman replay failed: {}\n{stdout}",
        String::from_utf8_lossy(&output.stderr)
    );
    let summary: serde_json::Value = serde_json::from_str(stdout.trim()).expect("summary JSON");
    assert_eq!(summary["frames"], 60);
    assert_eq!(summary["pngs"], 3);

    // The log: one JSON object per frame, in order.
    let log = std::fs::read_to_string(frames.join("frames.jsonl")).expect("log");
    let records: Vec<serde_json::Value> = log
        .lines()
        .map(|l| serde_json::from_str(l).expect("log line is JSON"))
        .collect();
    assert_eq!(records.len(), 60);
    let period = 1.0 / 60.0;
    for (n, r) in records.iter().enumerate() {
        assert_eq!(r["frame"], n as u64);
        // Offline pacing: the frame is drawn at n+1 frame periods (of whole nanoseconds); the
        // simulation has reached that time by real steps, and passed it by less than one step
        // (the character's steps are at most 16 ms, so each 16.7 ms frame takes one or more).
        let shown = r["shown_time_s"].as_f64().expect("shown time");
        assert!(
            (shown - period * (n as f64 + 1.0)).abs() < 1e-6,
            "frame {n}: drawn at {shown}"
        );
        let sim_time = r["sim_time_s"].as_f64().expect("sim time");
        assert!(
            sim_time >= shown - 1e-9 && sim_time < shown + 0.016,
            "frame {n}: simulated to {sim_time}, drawn at {shown}"
        );
        assert!(r["deforming"].as_bool().expect("deforming"));
        assert!(
            r["sim_steps"].as_u64().expect("steps") > 0,
            "frame {n} took no steps"
        );
        assert_eq!(r["skin_points"], 1024);
        assert!(r["render_wall_s"].as_f64().expect("render") > 0.0);
        // The second read is later in the session than the first.
        let first = r["first_read"]["read_at_s"].as_f64().expect("first read");
        let second = r["render_read"]["read_at_s"].as_f64().expect("second read");
        assert!((first - period * n as f64).abs() < 1e-6);
        assert!(second > first);
    }
    // The session's FASTRAK starts sending after its banner; from then on both head and wand
    // poses are used, fresh (FASTRAK gives each station 60 records a second).
    let tracked: Vec<&serde_json::Value> = records
        .iter()
        .filter(|r| !r["render_read"]["head"].is_null())
        .collect();
    assert!(
        tracked.len() >= 30,
        "only {} frames had a head pose",
        tracked.len()
    );
    let mut head_positions = Vec::new();
    let mut with_wand = 0;
    for r in &tracked {
        let head = &r["render_read"]["head"];
        let age = head["age_s"].as_f64().expect("age");
        assert!((0.0..0.1).contains(&age), "head sample {age} s old");
        if !r["render_read"]["wand"].is_null() {
            with_wand += 1;
        }
        head_positions.push(head["position_m"].to_string());
    }
    // Station 2 (the wand) starts a record or two after station 1.
    assert!(
        with_wand + 2 >= tracked.len(),
        "wand in only {with_wand} of {}",
        tracked.len()
    );
    head_positions.dedup();
    assert!(
        head_positions.len() > 10,
        "the head should move through the session"
    );

    // The frames: PNGs of the composed side-by-side image showing the skin in both halves.
    let pngs: Vec<_> = (0..60)
        .step_by(20)
        .map(|n| frames.join(format!("frame_{n:05}.png")))
        .collect();
    let mut images = Vec::new();
    for png in &pngs {
        let image = RgbaImage::load_png(png).expect("frame PNG");
        assert_eq!((image.width, image.height), (320, 180));
        let left = RgbaImage {
            width: 160,
            height: 180,
            pixels: image
                .pixels
                .chunks_exact(320 * 4)
                .flat_map(|row| row[..160 * 4].to_vec())
                .collect(),
        };
        let right = RgbaImage {
            width: 160,
            height: 180,
            pixels: image
                .pixels
                .chunks_exact(320 * 4)
                .flat_map(|row| row[160 * 4..].to_vec())
                .collect(),
        };
        for (half, name) in [(&left, "left"), (&right, "right")] {
            let skin = skin_pixels(half);
            assert!(
                skin > 160 * 180 / 50,
                "{}: only {skin} skin pixels in the {name} eye",
                png.display()
            );
        }
        images.push(image);
    }
    assert_ne!(images[0].pixels, images[2].pixels, "frames must change");
}

#[test]
fn a_missing_session_is_a_clear_error() {
    let output = Command::new(env!("CARGO_BIN_EXE_leman"))
        .current_dir(root())
        .args(["replay", "--headless", "no/such.session"])
        .output()
        .expect("run leman");
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("no/such.session"), "{stderr}");
}

#[test]
fn headless_replay_refuses_an_output_larger_than_the_device_allows_before_any_frame() {
    if !gpu_available() {
        return;
    }
    let (_dir, frames, runtime) = scratch();
    let run = |size: &str, stereo: &str| {
        Command::new(env!("CARGO_BIN_EXE_leman"))
            .current_dir(root())
            .env("XDG_RUNTIME_DIR", &runtime)
            .args(["replay", "--headless", "--no-sim", "--frame-count", "1"])
            .args(["--stereo", stereo, "--size", size, "--frames"])
            .arg(&frames)
            .arg("devices/sessions/opentrack.session")
            .output()
            .expect("leman runs")
    };
    // Side by side (full) doubles the width: 16384 pixels is past the renderer's 8192 cap on
    // any device. It used to "replay" every frame without rendering one, and exit 0.
    let out = run("8192x64", "sbs-full");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("a 8192×64 display in side by side (full) needs a 16384×64 image"),
        "{stderr}"
    );
    assert!(!frames.join("frame_00000.png").exists(), "no frame written");
    // Half as wide fits.
    let out = run("4096x64", "sbs-full");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(frames.join("frame_00000.png").exists());
}

#[test]
fn headless_replay_counts_the_frames_whose_simulation_stalled() {
    if !gpu_available() {
        return;
    }
    let (dir, frames, runtime) = scratch();
    let mut character =
        leman::character::Character::load(&root().join("assets/characters/torso_16.toml"))
            .expect("example loads");
    // Every tissue spring stretched by a kilometre: the guard gives up at every frame.
    for s in &mut character.shapes {
        s.joint_from_shape.position_m.y -= 1000.0;
    }
    let stalled = dir.path().join("stalled.toml");
    character.save(&stalled).expect("saved");
    let run = |character: &Path, json: bool| {
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_leman"));
        cmd.current_dir(root())
            .env("XDG_RUNTIME_DIR", &runtime)
            .args([
                "replay",
                "--headless",
                "--frame-count",
                "4",
                "--size",
                "64x48",
            ])
            .arg("--character")
            .arg(character)
            .arg("--frames")
            .arg(&frames)
            .arg("devices/sessions/opentrack.session");
        if json {
            cmd.arg("--json");
        }
        let out = cmd.output().expect("leman runs");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let text = run(&stalled, false);
    assert!(
        text.contains("warning: the simulation stalled in 4 of 4 frames, first at t = 0.0000 s"),
        "{text}"
    );
    // The replay steps with Verlet, which has no fixed step to blame.
    assert!(
        text.contains("the character's forces are out of range") && !text.contains("step_s"),
        "{text}"
    );
    let v: serde_json::Value = serde_json::from_str(&run(&stalled, true)).expect("JSON");
    assert_eq!(v["stalled_frames"], 4, "{v}");
    let fine = root().join("assets/characters/torso_16.toml");
    let v: serde_json::Value = serde_json::from_str(&run(&fine, true)).expect("JSON");
    assert_eq!(v["stalled_frames"], 0, "{v}");
    assert!(!run(&fine, false).contains("stalled"));
}
