//! `leman calibrate` end to end: `--check --json` on the default profile, `--corners` fits,
//! `--replay` of the committed corner-touching session, and clear errors.

use glam::{Mat4, Vec3, Vec4};
use leman::calibration::{CalibrationProfile, Corner};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn leman(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_leman"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("run leman")
}

fn ok_stdout(out: &Output) -> String {
    assert!(
        out.status.success(),
        "failed: {}\n{}",
        String::from_utf8_lossy(&out.stderr),
        String::from_utf8_lossy(&out.stdout)
    );
    String::from_utf8(out.stdout.clone()).expect("utf-8")
}

fn err_text(out: &Output) -> String {
    assert!(!out.status.success(), "should have failed");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn vec3(v: &Value) -> Vec3 {
    let a: Vec<f32> = v
        .as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().expect("number") as f32)
        .collect();
    assert_eq!(a.len(), 3);
    Vec3::new(a[0], a[1], a[2])
}

fn mat4(v: &Value) -> Mat4 {
    let a: Vec<f32> = v
        .as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().expect("number") as f32)
        .collect();
    assert_eq!(a.len(), 16);
    Mat4::from_cols_slice(&a)
}

#[test]
fn check_json_for_the_default_profile() {
    let out = leman(&[
        "calibrate",
        "--check",
        "--calibration",
        "calibration/desktop.toml",
        "--head",
        "0.05,0.02,0.6,0,0,0,1",
        "--near",
        "0.05",
        "--far",
        "20",
        "--json",
    ]);
    let json: Value = serde_json::from_str(&ok_stdout(&out)).expect("json");
    let s = &json["screen"];
    assert_eq!(vec3(&s["lower_left"]), Vec3::new(-0.265, -0.15, 0.0));
    assert_eq!(vec3(&s["lower_right"]), Vec3::new(0.265, -0.15, 0.0));
    assert_eq!(vec3(&s["upper_left"]), Vec3::new(-0.265, 0.15, 0.0));
    assert!((s["width_m"].as_f64().expect("w") - 0.53).abs() < 1e-6);
    assert!((s["height_m"].as_f64().expect("h") - 0.30).abs() < 1e-6);
    assert_eq!(s["residual_m"].as_f64(), Some(0.0));
    let corners = [
        (Vec3::new(-0.265, -0.15, 0.0), -1.0, -1.0),
        (Vec3::new(0.265, -0.15, 0.0), 1.0, -1.0),
        (Vec3::new(-0.265, 0.15, 0.0), -1.0, 1.0),
        (Vec3::new(0.265, 0.15, 0.0), 1.0, 1.0),
    ];
    for (eye, dx) in [("left", -0.0315), ("right", 0.0315)] {
        let e = &json["eyes"][eye];
        let p = vec3(&e["position_m"]);
        assert!(
            (p - Vec3::new(0.05 + dx, 0.02, 0.6)).length() < 1e-6,
            "{eye}: {p}"
        );
        let m = mat4(&e["clip_from_world"]);
        for (c, nx, ny) in corners {
            let clip = m * Vec4::new(c.x, c.y, c.z, 1.0);
            let ndc = clip.truncate() / clip.w;
            assert!(
                (ndc.x - nx).abs() < 1e-4 && (ndc.y - ny).abs() < 1e-4,
                "{eye} {ndc}"
            );
            assert!(ndc.z > 0.0 && ndc.z < 1.0);
        }
        // Near plane 0.05 m in front of the eye maps to depth 0.
        let near = m * (p - Vec3::Z * 0.05).extend(1.0);
        assert!((near.z / near.w).abs() < 1e-4);
    }
}

#[test]
fn check_text_and_default_head_and_bad_heads() {
    let text = ok_stdout(&leman(&["calibrate", "--check"]));
    assert!(text.contains("0.5300 m x 0.3000 m"), "{text}");
    assert!(text.contains("Left eye at [-0.0315, 0.0, 0.6]"), "{text}");
    let e = err_text(&leman(&["calibrate", "--check", "--head", "0,0,0.6,0,0,1"]));
    assert!(e.contains("7 numbers"), "{e}");
    let e = err_text(&leman(&[
        "calibrate",
        "--check",
        "--head",
        "0,0,0.6,0,0,0,2",
    ]));
    assert!(e.contains("unit quaternion"), "{e}");
    let e = err_text(&leman(&[
        "calibrate",
        "--check",
        "--calibration",
        "no/such.toml",
    ]));
    assert!(e.contains("no/such.toml"), "{e}");
}

fn write_corners(dir: &Path, name: &str, json: &Value) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, serde_json::to_string(json).expect("json")).expect("write");
    path
}

#[test]
fn corners_file_in_centimetres_is_fitted_and_saved() {
    let dir = tempfile::tempdir().expect("tempdir");
    // A 60 x 34 cm screen centred at (10, 120, -40) cm, facing +Z, a few samples per corner with
    // ±1 mm jitter and one 6 cm outlier.
    let corner = |x: f64, y: f64| -> Value {
        let mut v = Vec::new();
        for i in 0..6 {
            let j = [0.1, -0.1, 0.05, -0.05, 0.0, 0.08][i];
            v.push(serde_json::json!([10.0 + x + j, 120.0 + y - j, -40.0 + j]));
        }
        v.push(serde_json::json!([10.0 + x + 6.0, 120.0 + y, -40.0]));
        Value::Array(v)
    };
    let json = serde_json::json!({
        "units": "cm",
        "lower_left": corner(-30.0, -17.0),
        "lower_right": corner(30.0, -17.0),
        "upper_left": corner(-30.0, 17.0),
        "upper_right": corner(30.0, 17.0),
    });
    let file = write_corners(dir.path(), "corners.json", &json);
    let out_path = dir.path().join("bench.toml");
    let out = leman(&[
        "calibrate",
        "--corners",
        file.to_str().expect("path"),
        "--out",
        out_path.to_str().expect("path"),
        "--json",
    ]);
    let printed: Value = serde_json::from_str(&ok_stdout(&out)).expect("json");
    assert!((printed["screen"]["width_m"].as_f64().expect("w") - 0.60).abs() < 0.001);
    assert_eq!(printed["corners"][0]["rejected"].as_u64(), Some(1));
    let profile = CalibrationProfile::load(&out_path).expect("saved profile loads");
    let s = profile.screen;
    assert!((s.corner_m(Corner::LowerLeft) - Vec3::new(-0.2, 1.03, -0.4)).length() < 0.001);
    assert!((s.corner_m(Corner::UpperRight) - Vec3::new(0.4, 1.37, -0.4)).length() < 0.001);
    assert!((s.normal() - Vec3::Z).length() < 0.01);
    // Three corners are enough (upper_right may be absent).
    let mut three = json.clone();
    three.as_object_mut().expect("object").remove("upper_right");
    let file = write_corners(dir.path(), "three.json", &three);
    let printed: Value = serde_json::from_str(&ok_stdout(&leman(&[
        "calibrate",
        "--corners",
        file.to_str().expect("path"),
        "--json",
    ])))
    .expect("json");
    assert!((printed["screen"]["height_m"].as_f64().expect("h") - 0.34).abs() < 0.001);
}

#[test]
fn live_calibration_refuses_a_mouse_for_a_wand() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out_path = dir.path().join("cal.toml");
    let out = out_path.to_str().expect("utf-8 path");
    for profile in ["devices/desktop.toml", "devices/opentrack-spacemouse.toml"] {
        let err = err_text(&leman(&["calibrate", "--profile", profile, "--out", out]));
        assert!(
            err.contains(profile) && err.contains("no 3D") && err.contains("\"desktop\""),
            "{err}"
        );
    }
    assert!(!out_path.exists(), "nothing written");
}

#[test]
fn bad_corner_files_fail_clearly() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out_path = dir.path().join("never.toml");
    let run = |json: Value, name: &str| {
        let file = write_corners(dir.path(), name, &json);
        err_text(&leman(&[
            "calibrate",
            "--corners",
            file.to_str().expect("path"),
            "--out",
            out_path.to_str().expect("path"),
        ]))
    };
    let e = run(
        serde_json::json!({"units": "m", "lower_left": [[0, 0, 0]], "lower_right": [[0.5, 0, 0]]}),
        "missing.json",
    );
    assert!(
        e.contains("missing.json") && e.contains("upper_left"),
        "{e}"
    );
    let e = run(
        serde_json::json!({"units": "m", "lower_left": [[0, 0, 0]], "lower_right": [[0.5, 0, 0]],
            "upper_left": []}),
        "two.json",
    );
    assert!(e.contains("at least three"), "{e}");
    let e = run(
        serde_json::json!({"units": "mm", "lower_left": [], "lower_right": [], "upper_left": []}),
        "units.json",
    );
    assert!(e.contains("units.json"), "{e}");
    let e = run(
        serde_json::json!({"units": "m", "lower_left": [[0, 0, 0]], "lower_right": [[53, 0, 0]],
            "upper_left": [[0, 30, 0]]}),
        "huge.json",
    );
    assert!(e.contains("units"), "{e}");
    let e = run(
        serde_json::json!({"units": "m", "lower_left": [[0, 0, 0]], "lower_right": [[0.5, 0, 0]],
            "upper_left": [[1.0, 0.0, 0]]}),
        "line.json",
    );
    assert!(e.contains("collinear"), "{e}");
    assert!(!out_path.exists(), "nothing written on failure");
    // Left and right swapped: a valid rectangle facing away from the viewer, with a warning.
    let mirrored = serde_json::json!({"units": "m",
        "lower_left": [[0.265, -0.15, 0]], "lower_right": [[-0.265, -0.15, 0]],
        "upper_left": [[0.265, 0.15, 0]], "upper_right": [[-0.265, 0.15, 0]]});
    let file = write_corners(dir.path(), "mirrored.json", &mirrored);
    let out = leman(&[
        "calibrate",
        "--corners",
        file.to_str().expect("path"),
        "--json",
    ]);
    ok_stdout(&out);
    let warning = String::from_utf8_lossy(&out.stderr);
    assert!(warning.contains("mirrored order"), "{warning}");
}

#[test]
fn replayed_session_writes_the_expected_profile() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out_path = dir.path().join("replayed.toml");
    let text = ok_stdout(&leman(&[
        "calibrate",
        "--replay",
        "calibration/sessions/touch-corners.session",
        "--calibration",
        "calibration/fastrak-desk.toml",
        "--out",
        out_path.to_str().expect("path"),
    ]));
    assert!(text.contains("press ignored: the wand is moving"), "{text}");
    assert!(text.contains("accepted"), "{text}");
    let got = CalibrationProfile::load(&out_path).expect("written profile");
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let want = CalibrationProfile::load(&root.join("calibration/fastrak-desk.toml")).expect("p");
    for c in Corner::ALL {
        let e = (got.screen.corner_m(c) - want.screen.corner_m(c)).length();
        assert!(e < 0.0015, "{c}: {e} m");
    }
    assert_eq!(
        got.tracker, want.tracker,
        "tracker frames kept from the base profile"
    );
    assert!(got.residual_m < 0.001);
    // Live without a device profile says what to do.
    let e = err_text(&leman(&[
        "calibrate",
        "--out",
        out_path.to_str().expect("path"),
    ]));
    assert!(e.contains("--profile"), "{e}");
    // A session holds its own device profile: one passed beside it would be ignored, so the
    // two are refused together rather than the profile silently dropped.
    let e = err_text(&leman(&[
        "calibrate",
        "--profile",
        "devices/fastrak-spaceball.toml",
        "--replay",
        "calibration/sessions/touch-corners.session",
        "--out",
        out_path.to_str().expect("path"),
    ]));
    assert!(
        e.contains("--profile") && e.contains("cannot be used with") && e.contains("--replay"),
        "{e}"
    );
}
