//! The real `leman` window under Xvfb: starts `leman run` on a virtual X display (wgpu on
//! lavapipe), takes screenshots of the root window with ImageMagick's `import` until the
//! character's skin shows, and keeps the last one in `target/ui_window_screenshot.png`.
//!
//! Without Xvfb, `import` or a GPU driver the test prints a loud SKIPPED, unless
//! `LEMAN_REQUIRE_GPU=1`, when it fails.

use leman::render::RgbaImage;
use leman::render::device_caps::gpu_required_by_env;
use std::path::{Path, PathBuf};
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

fn start_xvfb() -> Option<(Killed, String)> {
    for n in 90..200u32 {
        let socket = PathBuf::from(format!("/tmp/.X11-unix/X{n}"));
        let lock = PathBuf::from(format!("/tmp/.X{n}-lock"));
        if socket.exists() || lock.exists() {
            continue;
        }
        let child = Command::new("Xvfb")
            .args([
                &format!(":{n}"),
                "-screen",
                "0",
                "1280x720x24",
                "-nolisten",
                "tcp",
            ])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .ok()?;
        let guard = Killed(child);
        let start = Instant::now();
        while start.elapsed() < Duration::from_secs(10) {
            if socket.exists() {
                return Some((guard, format!(":{n}")));
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        return None;
    }
    None
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
    let Some((_xvfb, display)) = start_xvfb() else {
        skip("Xvfb did not start");
        return;
    };
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().expect("tempdir");
    let runtime = dir.path().join("xdg");
    std::fs::create_dir_all(&runtime).expect("runtime dir");
    let log = dir.path().join("leman.log");
    let mut leman = Killed(
        Command::new(env!("CARGO_BIN_EXE_leman"))
            .current_dir(root)
            .env("DISPLAY", &display)
            .env("XDG_RUNTIME_DIR", &runtime)
            .env_remove("WAYLAND_DISPLAY")
            .args(["run", "--size", "1280x720", "--quit-after-frames", "5000"])
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(&log).expect("log file"))
            .spawn()
            .expect("start leman"),
    );
    let shot = dir.path().join("shot.png");
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
            .env("DISPLAY", &display)
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
