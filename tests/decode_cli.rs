//! `leman decode` end to end: small capture files made with the library's encoders, decoded by
//! the real binary.

use leman::devices::encode;
use leman::devices::fastrak::{FastrakFormat, FastrakSettings};
use std::path::Path;
use std::process::Command;

fn leman(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_leman"))
        .args(args)
        .output()
        .expect("run leman");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn json_lines(stdout: &str) -> Vec<serde_json::Value> {
    stdout
        .lines()
        .map(|l| serde_json::from_str(l).expect("every line is JSON"))
        .collect()
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> String {
    let path = dir.join(name);
    std::fs::write(&path, bytes).expect("write capture");
    path.to_string_lossy().into_owned()
}

#[test]
fn fastrak_ascii_capture_decodes_to_json_in_arrival_order() {
    let dir = tempfile::tempdir().expect("tempdir");
    let record = encode::fastrak::FastrakRecord {
        station: 1,
        status: b' ',
        position: [12.0, -3.5, 10.0],
        euler_deg: [90.0, 0.0, 0.0],
        quaternion: [1.0, 0.0, 0.0, 0.0],
        stylus: false,
    };
    let one =
        encode::fastrak::encode_record(FastrakFormat::Ascii, &FastrakSettings::default(), &record);
    let mut bytes = b"zz".to_vec();
    bytes.extend(&one);
    bytes.extend(&one[..10]);
    let file = write(dir.path(), "fastrak.bin", &bytes);
    let (ok, stdout, stderr) = leman(&["decode", "--protocol", "fastrak-ascii", &file, "--json"]);
    assert!(ok, "{stderr}");
    let lines = json_lines(&stdout);
    assert_eq!(lines.len(), 3, "{stdout}");
    assert_eq!(lines[0]["kind"], "dropped");
    assert_eq!(lines[0]["bytes"], 2);
    assert_eq!(lines[1]["kind"], "pose");
    assert_eq!(lines[1]["station"], 1);
    assert_eq!(
        lines[1]["raw_position"],
        serde_json::json!([12.0, -3.5, 10.0])
    );
    assert_eq!(
        lines[1]["raw_euler_deg"],
        serde_json::json!([90.0, 0.0, 0.0])
    );
    // 12 in forward, -3.5 in right, 10 in down -> x = -0.0889, y = -0.254, z = -0.3048 m.
    let p = &lines[1]["position_m"];
    for (i, want) in [-0.0889, -0.254, -0.3048].into_iter().enumerate() {
        assert!(
            (p[i].as_f64().unwrap_or(f64::NAN) - want).abs() < 1e-6,
            "{p}"
        );
    }
    let q = &lines[1]["orientation_xyzw"];
    assert!(
        (q[1].as_f64().unwrap_or(0.0) + 0.5f64.sqrt()).abs() < 1e-6,
        "{q}"
    );
    // The truncated record at the end of the file is reported, not silently lost.
    assert_eq!(
        lines[2],
        serde_json::json!({"kind": "dropped", "bytes": 10})
    );
    assert!(stdout.lines().all(|l| l.starts_with("{\"kind\":")));

    // Fragmented reads give the same events; the readable form has one line per event.
    let (_, chunked, _) = leman(&[
        "decode",
        "-p",
        "fastrak-ascii",
        &file,
        "--json",
        "--chunk",
        "1",
    ]);
    assert_eq!(chunked, stdout);
    let (ok, text, _) = leman(&["decode", "-p", "fastrak-ascii", &file]);
    assert!(ok);
    assert_eq!(text.lines().count(), 3);
    assert!(
        text.lines().nth(1).unwrap_or("").starts_with("pose"),
        "{text}"
    );
}

#[test]
fn fastrak_binary_output_list_and_stylus_flags() {
    let dir = tempfile::tempdir().expect("tempdir");
    let settings = FastrakSettings {
        items: vec![2, 11, 16, 1],
        stylus_bytes: 1,
        ..FastrakSettings::default()
    };
    let record = encode::fastrak::FastrakRecord {
        station: 3,
        status: b' ',
        position: [1.0, 2.0, 3.0],
        euler_deg: [0.0; 3],
        quaternion: [1.0, 0.0, 0.0, 0.0],
        stylus: true,
    };
    let bytes = encode::fastrak::encode_record(FastrakFormat::Binary, &settings, &record);
    let file = write(dir.path(), "fastrak.bin", &bytes);
    let args = [
        "decode",
        "-p",
        "fastrak-binary",
        &file,
        "--json",
        "--fastrak-items",
        "2,11,16,1",
        "--stylus-bytes",
        "1",
        "--fastrak-units",
        "cm",
    ];
    let (ok, stdout, stderr) = leman(&args);
    assert!(ok, "{stderr}");
    let lines = json_lines(&stdout);
    assert_eq!(lines.len(), 1, "{stdout}");
    assert_eq!(lines[0]["station"], 3);
    assert_eq!(lines[0]["pressed"], serde_json::json!([0]));
    assert_eq!(
        lines[0]["raw_quaternion"],
        serde_json::json!([1.0, 0.0, 0.0, 0.0])
    );
    // cm: 1 cm forward, 2 right, 3 down -> (0.02, -0.03, -0.01) m.
    assert_eq!(
        lines[0]["position_m"],
        serde_json::json!([0.02, -0.03, -0.01])
    );
    // The default (2-byte stylus, 2,4,1) does not find this record.
    let (ok, stdout, _) = leman(&["decode", "-p", "fastrak-binary", &file, "--json"]);
    assert!(ok);
    assert!(
        json_lines(&stdout).iter().all(|l| l["kind"] == "dropped"),
        "{stdout}"
    );
    // Bad settings are refused with a message.
    let (ok, _, stderr) = leman(&[
        "decode",
        "-p",
        "fastrak-binary",
        &file,
        "--stylus-bytes",
        "3",
    ]);
    assert!(!ok);
    assert!(stderr.contains("stylus"), "{stderr}");
}

#[test]
fn hid_opentrack_and_spaceball_captures() {
    let dir = tempfile::tempdir().expect("tempdir");
    let [t, r] = encode::spacemouse_hid::split_reports([100, -50, 400, 7, -8, 9]);
    let reports = vec![
        t,
        r,
        encode::spacemouse_hid::buttons_report(&[0, 2], 2),
        encode::spacemouse_hid::combined_report([1, 2, 3, 4, 5, 6]),
        vec![9, 9, 9],
    ];
    let file = write(
        dir.path(),
        "hid.bin",
        &encode::spacemouse_hid::length_prefixed(&reports),
    );
    let (ok, stdout, stderr) = leman(&["decode", "-p", "spacemouse-hid", &file, "--json"]);
    assert!(ok, "{stderr}");
    let lines = json_lines(&stdout);
    let kinds: Vec<&str> = lines.iter().filter_map(|l| l["kind"].as_str()).collect();
    assert_eq!(kinds, ["axes", "axes", "buttons", "axes"], "{stdout}");
    assert_eq!(
        lines[1]["raw"],
        serde_json::json!([100, -50, 400, 7, -8, 9])
    );
    assert_eq!(lines[2]["pressed"], serde_json::json!([0, 2]));
    assert_eq!(lines[3]["raw"], serde_json::json!([1, 2, 3, 4, 5, 6]));

    let mut bytes = encode::opentrack::datagram([10.0, -5.0, 60.0, 90.0, 0.0, 0.0]).to_vec();
    bytes.extend(encode::opentrack::datagram([
        0.0,
        0.0,
        f64::NAN,
        0.0,
        0.0,
        0.0,
    ]));
    let file = write(dir.path(), "opentrack.bin", &bytes);
    let (ok, stdout, _) = leman(&["decode", "-p", "opentrack", &file, "--json"]);
    assert!(ok);
    let lines = json_lines(&stdout);
    assert_eq!(lines.len(), 3, "{stdout}");
    assert_eq!(lines[0]["position_m"], serde_json::json!([0.1, -0.05, 0.6]));
    assert!(lines[1]["text"].as_str().unwrap_or("").contains("NaN"));
    assert_eq!(
        lines[2],
        serde_json::json!({"kind": "dropped", "bytes": 48})
    );

    let mut bytes = encode::spaceball::encode_banner("2.43");
    bytes.extend(encode::spaceball::encode_d(0, [0x0D0D, 0, 0, 0, 0, 0]));
    let file = write(dir.path(), "spaceball.bin", &bytes);
    let (ok, stdout, _) = leman(&["decode", "-p", "spaceball", &file, "--json"]);
    assert!(ok);
    let lines = json_lines(&stdout);
    assert_eq!(lines[1]["model"], "Spaceball 4000FLX");
    assert_eq!(lines[2]["raw"], serde_json::json!([0x0D0D, 0, 0, 0, 0, 0]));
}

#[test]
fn errors_name_the_problem() {
    let (ok, _, stderr) = leman(&["decode", "-p", "spaceorb", "Cargo.toml"]);
    assert!(!ok);
    assert!(stderr.contains("spacemouse-hid"), "{stderr}");
    let (ok, _, stderr) = leman(&["decode", "-p", "spaceball", "/nonexistent/capture.bin"]);
    assert!(!ok);
    assert!(stderr.contains("/nonexistent/capture.bin"), "{stderr}");
    let (ok, _, stderr) = leman(&["decode", "Cargo.toml"]);
    assert!(!ok);
    assert!(stderr.contains("--protocol"), "{stderr}");
}

#[test]
fn session_files_decode_every_device_with_times() {
    let session = Path::new(env!("CARGO_MANIFEST_DIR")).join("devices/sessions/spaceball.session");
    if !session.exists() {
        panic!("sample session {} is missing", session.display());
    }
    let path = session.to_string_lossy();
    let (ok, stdout, stderr) = leman(&["decode", &path, "--json"]);
    assert!(ok, "{stderr}");
    let lines = json_lines(&stdout);
    assert!(
        lines.iter().any(|l| l["model"] == "Spaceball 4000FLX"),
        "{stdout}"
    );
    assert!(lines.iter().filter(|l| l["kind"] == "axes").count() >= 10);
    let times: Vec<f64> = lines.iter().filter_map(|l| l["t_s"].as_f64()).collect();
    assert_eq!(times.len(), lines.len());
    assert!(times.windows(2).all(|w| w[0] <= w[1]));
    // Selecting a protocol no device speaks is an error.
    let (ok, _, stderr) = leman(&["decode", "-p", "opentrack", &path]);
    assert!(!ok);
    assert!(stderr.contains("opentrack"), "{stderr}");
}
