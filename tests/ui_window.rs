//! The real `leman` window under Xvfb: starts `leman run` on a virtual X display (wgpu on
//! lavapipe), takes screenshots of the root window with ImageMagick's `import` until the
//! character's skin shows, and keeps the last one in `target/ui_window_screenshot.png`.
//!
//! Without Xvfb, `import` or a GPU driver the test prints a loud SKIPPED, unless
//! `LEMAN_REQUIRE_GPU=1`, when it fails.

use leman::render::RgbaImage;
use leman::render::device_caps::gpu_required_by_env;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Kills the child when dropped (also when the test fails).
struct Killed(Child);

impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn skip(why: &str) {
    if gpu_required_by_env() {
        panic!("LEMAN_REQUIRE_GPU=1 but {why}");
    }
    eprintln!("\n*** SKIPPED ui_window: {why}. ***\n");
}

fn have(program: &str) -> bool {
    Command::new("sh")
        .args(["-c", &format!("command -v {program}")])
        .stdout(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
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

/// Starts Xvfb on a display number it picks itself (`-displayfd`: two tests starting one each
/// at once cannot pick the same one) and returns it with its `DISPLAY` name.
fn start_xvfb() -> Option<(Killed, String)> {
    let mut child = Command::new("Xvfb")
        .args([
            "-displayfd",
            "1",
            "-screen",
            "0",
            "1280x720x24",
            "-nolisten",
            "tcp",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .ok()?;
    let stdout = child.stdout.take()?;
    let guard = Killed(child);
    // Xvfb writes the number once it accepts connections; a failed start closes the pipe.
    let mut line = String::new();
    std::io::BufRead::read_line(&mut std::io::BufReader::new(stdout), &mut line).ok()?;
    let n: u32 = line.trim().parse().ok()?;
    Some((guard, format!(":{n}")))
}

/// A virtual X display with a private runtime folder, for `leman` windows.
struct VirtualDisplay {
    _xvfb: Killed,
    display: String,
    dir: tempfile::TempDir,
}

impl VirtualDisplay {
    /// Starts one, or says why not (`skip`) and gives `None`.
    fn start() -> Option<Self> {
        let Some((xvfb, display)) = start_xvfb() else {
            skip("Xvfb did not start");
            return None;
        };
        let dir = tempfile::tempdir().expect("tempdir");
        std::fs::create_dir_all(dir.path().join("xdg")).expect("runtime dir");
        Some(Self {
            _xvfb: xvfb,
            display,
            dir,
        })
    }

    /// A scratch folder that lives as long as the display.
    fn dir(&self) -> &Path {
        self.dir.path()
    }

    /// `leman ARGS` on this display, from the crate's folder.
    fn leman(&self, args: &[&str]) -> Command {
        let mut command = Command::new(env!("CARGO_BIN_EXE_leman"));
        command
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .env("DISPLAY", &self.display)
            .env("XDG_RUNTIME_DIR", self.dir().join("xdg"))
            .env_remove("WAYLAND_DISPLAY")
            .args(args);
        command
    }
}

#[test]
fn the_leman_window_shows_the_character() {
    for program in ["Xvfb", "import"] {
        if !have(program) {
            skip(&format!(
                "`{program}` is not installed (apt-get install xvfb imagemagick)"
            ));
            return;
        }
    }
    let Some(x) = VirtualDisplay::start() else {
        return;
    };
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let log = x.dir().join("leman.log");
    let mut leman = Killed(
        x.leman(&["run", "--size", "1280x720", "--quit-after-frames", "5000"])
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&log).expect("log file"))
            .spawn()
            .expect("start leman"),
    );
    let shot = x.dir().join("shot.png");
    let keep = root.join("target/ui_window_screenshot.png");
    let start = Instant::now();
    let mut best = 0;
    while start.elapsed() < Duration::from_secs(150) {
        std::thread::sleep(Duration::from_secs(3));
        if let Ok(Some(status)) = leman.0.try_wait() {
            let text = std::fs::read_to_string(&log).unwrap_or_default();
            if text.contains("NotFound") || text.contains("No suitable") || text.contains("adapter")
            {
                skip(&format!("no GPU for the window: {text}"));
                return;
            }
            panic!("leman exited early ({status}):\n{text}");
        }
        let ok = Command::new("import")
            .env("DISPLAY", &x.display)
            .args(["-window", "root"])
            .arg(&shot)
            .status()
            .is_ok_and(|s| s.success());
        if !ok {
            continue;
        }
        let Ok(image) = RgbaImage::load_png(&shot) else {
            continue;
        };
        let skin = skin_pixels(&image);
        best = best.max(skin);
        // The torso fills a good part of the 3D view: ask for 2% of the screen.
        if skin > (image.width * image.height / 50) as usize {
            let _ = std::fs::copy(&shot, &keep);
            eprintln!(
                "window shows the character: {skin} skin pixels; screenshot {}",
                keep.display()
            );
            return;
        }
    }
    let text = std::fs::read_to_string(&log).unwrap_or_default();
    let _ = std::fs::copy(&shot, &keep);
    panic!(
        "no character on screen after 150 s (best {best} skin pixels); screenshot {}\n{text}",
        keep.display()
    );
}

/// `leman run --record` writes the live devices (here the desktop stand-ins and the default
/// profile's absent SpaceMouse) into a whole session when the window closes, which loads and
/// holds the default profile; the same command again is refused before any window opens.
#[test]
fn leman_run_records_its_devices_into_a_session() {
    use leman::devices::session::{Record, Session};
    if !have("Xvfb") {
        skip("`Xvfb` is not installed (apt-get install xvfb)");
        return;
    }
    let Some(x) = VirtualDisplay::start() else {
        return;
    };
    let out = x.dir().join("desk.session");
    let run = || {
        x.leman(&["run", "--size", "320x180", "--quit-after-frames", "10"])
            .arg("--record")
            .arg(&out)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start leman")
    };
    let mut leman = Killed(run());
    let start = Instant::now();
    let status = loop {
        if let Some(status) = leman.0.try_wait().expect("wait") {
            break status;
        }
        assert!(
            start.elapsed() < Duration::from_secs(150),
            "leman run did not close after 10 frames"
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    let mut err = String::new();
    std::io::Read::read_to_string(leman.0.stderr.as_mut().expect("stderr"), &mut err)
        .expect("read stderr");
    if !status.success()
        && (err.contains("NotFound") || err.contains("No suitable") || err.contains("adapter"))
    {
        skip(&format!("no GPU for the window: {err}"));
        return;
    }
    assert!(status.success(), "{err}");
    assert!(err.contains("recorded "), "{err}");
    let session = Session::load(&out).expect("a whole session");
    let default = leman::devices::found::default_profile();
    assert_eq!(session.header.profile, default);
    let desktop = default.device_index("desktop").expect("desktop device");
    assert!(
        session
            .records
            .iter()
            .any(|r| matches!(r, Record::Opened { device, .. } if *device == desktop)),
        "{:?}",
        session.records
    );
    let partials = std::fs::read_dir(x.dir())
        .expect("list")
        .filter(|e| {
            e.as_ref()
                .is_ok_and(|e| e.file_name().to_string_lossy().ends_with(".partial"))
        })
        .count();
    assert_eq!(partials, 0, "the partial file is renamed into place");

    // Again into the same file: refused before a window opens, the session left as it is.
    let before = std::fs::read(&out).expect("read");
    let again = run().wait_with_output().expect("run again");
    assert!(!again.status.success());
    let err = String::from_utf8_lossy(&again.stderr);
    assert!(
        err.contains("already exists") && err.contains("--overwrite"),
        "{err}"
    );
    assert_eq!(std::fs::read(&out).expect("reread"), before);
}
