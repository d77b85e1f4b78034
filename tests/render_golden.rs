//! Golden-image tests of the renderer on a CPU adapter (Mesa lavapipe): the reference scene in
//! every stereo mode, compared with committed PNGs in `tests/golden/` (per-pixel tolerance and a
//! maximum fraction of differing pixels), plus checks that each mode composes the eyes as it
//! should (anaglyph channels, interleaved rows, side-by-side halves, alternating frames) and that
//! a NaN vertex never reaches the GPU. Where the machine also has GL, the GL path (a refreshed
//! copy behind the shown view) is checked on it too.
//!
//! Environment: `LEMAN_UPDATE_GOLDEN=1` rewrites the goldens; a missing golden is written (and is
//! a failure when `LEMAN_REQUIRE_GPU=1`, as in CI). Without any GPU driver the tests print a loud
//! SKIPPED, unless `LEMAN_REQUIRE_GPU=1`, when they fail. On a mismatch the actual image and a
//! diff image are saved under `target/render_golden/`.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use glam::Vec3;
use leman::calibration::{CalibrationProfile, ScreenRect};
use leman::pose::Pose;
use leman::render::device_caps::gpu_required_by_env;
use leman::render::reference::reference_scene;
use leman::render::{
    AdapterPreference, DrawPass, GpuContext, Renderer, RendererOptions, RgbaImage, Scene,
};
use leman::stereo::{
    Composition, OutputSettings, StereoMode, StereoViews, ViewSettings, compose, eye_views_for,
};

const WIDTH: u32 = 320;
const HEIGHT: u32 = 180;
/// Largest per-channel difference that still counts as the same pixel.
const CHANNEL_TOLERANCE: u8 = 10;
/// Largest fraction of pixels allowed to differ beyond the tolerance on Vulkan, where the
/// goldens were made (Mesa lavapipe).
const MAX_DIFFERING_FRACTION: f64 = 0.003;
/// The same on other backends. GL rasterizes one-pixel lines by other rules than Vulkan (Mesa
/// llvmpipe on GL moved 0.4 % of the pixels of `eye_left`, all of them on the skeleton's and
/// grid's lines, none on the shaded surfaces).
const MAX_DIFFERING_FRACTION_OTHER_BACKENDS: f64 = 0.012;

/// The differing fraction allowed on `backend`.
fn max_differing_fraction(backend: wgpu::Backend) -> f64 {
    match backend {
        wgpu::Backend::Vulkan => MAX_DIFFERING_FRACTION,
        _ => MAX_DIFFERING_FRACTION_OTHER_BACKENDS,
    }
}

/// Prints a skip where it is seen: written to the stderr handle directly, since libtest
/// captures `eprintln!`.
fn say_skipped(what: &str) {
    use std::io::Write;
    let _ = writeln!(std::io::stderr(), "\n*** SKIPPED {what} ***\n");
}

#[allow(unsafe_code)]
fn private_runtime_dir() {
    static ONCE: OnceLock<()> = OnceLock::new();
    ONCE.get_or_init(|| {
        let ok = std::env::var_os("XDG_RUNTIME_DIR").is_some_and(|d| Path::new(&d).is_dir());
        if !ok {
            let dir = std::env::temp_dir().join(format!("leman-xdg-{}", std::process::id()));
            std::fs::create_dir_all(&dir).expect("create runtime dir");
            // SAFETY: done once, before this test binary creates any GPU instance; the only
            // other readers are the test threads, which all pass through this OnceLock first.
            unsafe { std::env::set_var("XDG_RUNTIME_DIR", &dir) };
        }
    });
}

/// The shared device, or `None` after printing a loud skip (panics when a GPU is required).
fn gpu() -> Option<&'static GpuContext> {
    static GPU: OnceLock<Option<GpuContext>> = OnceLock::new();
    private_runtime_dir();
    GPU.get_or_init(|| match GpuContext::new_headless() {
        Ok(g) => {
            eprintln!("render tests on: {}", g.summary);
            Some(g)
        }
        Err(e) if gpu_required_by_env() => panic!("LEMAN_REQUIRE_GPU=1 but no GPU: {e}"),
        Err(e) => {
            say_skipped(&format!("render golden tests: {e}"));
            None
        }
    })
    .as_ref()
}

/// Eye views of the reference viewer (head 0.6 m in front of the default screen, a little to
/// the right and up) through a window 20% larger than the screen, so the screen's border is
/// inside the image.
fn reference_views() -> StereoViews {
    let profile = CalibrationProfile::default();
    let window = ScreenRect::desktop(0.53 * 1.2, 0.30 * 1.2).expect("window");
    let head = Pose::from_translation(Vec3::new(0.03, 0.05, 0.6));
    eye_views_for(
        &window,
        &profile.head_eyes,
        profile.baseline,
        &head,
        &ViewSettings::default(),
    )
    .expect("views")
}

fn recipe(mode: StereoMode, swap_eyes: bool) -> Composition {
    compose(
        &reference_views(),
        &OutputSettings { mode, swap_eyes },
        [WIDTH, HEIGHT],
    )
}

fn render_recipe(gpu: &GpuContext, scene: &Scene, c: &Composition, frame: u64) -> RgbaImage {
    let mut r = Renderer::new(&gpu.device, &gpu.queue, RendererOptions::default()).expect("r");
    let target = r
        .create_target(c.output_size_px[0], c.output_size_px[1])
        .expect("target");
    r.prepare(scene);
    r.draw_composition(&target, c, frame).expect("draw");
    r.read_image(&target).expect("read")
}

fn render_single(gpu: &GpuContext, scene: &Scene, pass: DrawPass) -> RgbaImage {
    let mut r = Renderer::new(&gpu.device, &gpu.queue, RendererOptions::default()).expect("r");
    let target = r.create_target(WIDTH, HEIGHT).expect("target");
    let report = r.render(&target, scene, &[pass]).expect("draw");
    assert_eq!(report.passes, 1);
    r.read_image(&target).expect("read")
}

fn eye_image(gpu: &GpuContext, view: &leman::stereo::EyeView) -> RgbaImage {
    render_single(
        gpu,
        &reference_scene(),
        DrawPass::full(view.clip_from_world, view.position_m, WIDTH, HEIGHT),
    )
}

fn golden_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/golden")
}

fn failure_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/render_golden")
}

/// Pixels whose largest channel difference exceeds the tolerance, and a diff image (differing
/// pixels magenta over a dimmed copy of the expected image).
fn compare(expected: &RgbaImage, actual: &RgbaImage) -> (usize, RgbaImage) {
    assert_eq!(
        (expected.width, expected.height),
        (actual.width, actual.height),
        "image size"
    );
    let mut differing = 0;
    let mut diff = expected.clone();
    for (i, (e, a)) in expected
        .pixels
        .chunks_exact(4)
        .zip(actual.pixels.chunks_exact(4))
        .enumerate()
    {
        let worst = e
            .iter()
            .zip(a)
            .map(|(x, y)| x.abs_diff(*y))
            .max()
            .unwrap_or(0);
        let d = &mut diff.pixels[i * 4..i * 4 + 4];
        if worst > CHANNEL_TOLERANCE {
            differing += 1;
            d.copy_from_slice(&[255, 0, 255, 255]);
        } else {
            for c in &mut d[..3] {
                *c /= 3;
            }
        }
    }
    (differing, diff)
}

/// Compares an image of the shared device with `tests/golden/NAME.png`, writing it when
/// missing or asked to.
fn check_golden(name: &str, actual: &RgbaImage) {
    let backend = gpu().map_or(wgpu::Backend::Vulkan, |g| g.summary.backend);
    check_golden_on(backend, name, actual);
}

/// [`check_golden`] for an image rendered on `backend`.
fn check_golden_on(backend: wgpu::Backend, name: &str, actual: &RgbaImage) {
    let max_fraction = max_differing_fraction(backend);
    let path = golden_dir().join(format!("{name}.png"));
    let update = std::env::var("LEMAN_UPDATE_GOLDEN").is_ok_and(|v| v == "1");
    if update || !path.exists() {
        std::fs::create_dir_all(golden_dir()).expect("golden dir");
        actual.save_png(&path).expect("write golden");
        eprintln!("wrote golden {}", path.display());
        assert!(
            update || !gpu_required_by_env(),
            "golden {} was missing (written now); commit it",
            path.display()
        );
        return;
    }
    let expected = RgbaImage::load_png(&path).expect("load golden");
    let (differing, diff) = compare(&expected, actual);
    let fraction = differing as f64 / (actual.width * actual.height) as f64;
    if fraction > max_fraction {
        std::fs::create_dir_all(failure_dir()).expect("failure dir");
        let actual_path = failure_dir().join(format!("{name}.actual.png"));
        let diff_path = failure_dir().join(format!("{name}.diff.png"));
        actual.save_png(&actual_path).expect("save actual");
        diff.save_png(&diff_path).expect("save diff");
        panic!(
            "{name}: {differing} pixels ({:.3}%) differ by more than {CHANNEL_TOLERANCE}; see {} and {}",
            fraction * 100.0,
            actual_path.display(),
            diff_path.display()
        );
    }
}

fn channel(img: &RgbaImage, c: usize) -> Vec<u8> {
    img.pixels.chunks_exact(4).map(|p| p[c]).collect()
}

fn row(img: &RgbaImage, y: u32) -> &[u8] {
    let w = (img.width * 4) as usize;
    &img.pixels[y as usize * w..(y as usize + 1) * w]
}

/// The sub-image `[x0, x0+w) × [y0, y0+h)`.
fn crop(img: &RgbaImage, x0: u32, y0: u32, w: u32, h: u32) -> RgbaImage {
    let mut pixels = Vec::with_capacity((w * h * 4) as usize);
    for y in y0..y0 + h {
        let r = row(img, y);
        pixels.extend_from_slice(&r[(x0 * 4) as usize..((x0 + w) * 4) as usize]);
    }
    RgbaImage {
        width: w,
        height: h,
        pixels,
    }
}

fn differing_pixels(a: &RgbaImage, b: &RgbaImage) -> usize {
    compare(a, b).0
}

/// The images are the same within the per-channel tolerance (a viewport offset may round a
/// colour slightly differently); reports counts, not pixels.
fn assert_same(a: &RgbaImage, b: &RgbaImage, what: &str) {
    assert_eq!((a.width, a.height), (b.width, b.height), "{what}: size");
    let exact = a
        .pixels
        .chunks_exact(4)
        .zip(b.pixels.chunks_exact(4))
        .filter(|(x, y)| x != y)
        .count();
    let n = differing_pixels(a, b);
    assert!(
        n == 0,
        "{what}: {n} pixels differ beyond tolerance ({exact} at all)"
    );
}

/// Same for one channel (or rows): `a` and `b` are byte sequences of equal length.
fn assert_same_bytes(a: &[u8], b: &[u8], what: &str) {
    assert_eq!(a.len(), b.len(), "{what}: length");
    let n = a
        .iter()
        .zip(b)
        .filter(|(x, y)| x.abs_diff(**y) > CHANNEL_TOLERANCE)
        .count();
    assert!(n == 0, "{what}: {n} values differ");
}

/// Pixels that are not the background (something was drawn there).
fn drawn_pixels(img: &RgbaImage) -> usize {
    let bg = img.pixel(0, 0).expect("corner");
    img.pixels
        .chunks_exact(4)
        .filter(|p| p[..3] != bg[..3])
        .count()
}

#[test]
fn every_stereo_mode_matches_its_golden_and_composes_the_eyes() {
    let Some(gpu) = gpu() else { return };
    let views = reference_views();
    let left = eye_image(gpu, &views.left);
    let right = eye_image(gpu, &views.right);
    check_golden("eye_left", &left);
    check_golden("eye_right", &right);
    // The eyes see the scene from 63 mm apart: plenty of pixels differ, and both show a scene.
    assert!(drawn_pixels(&left) > (WIDTH * HEIGHT / 20) as usize);
    let parallax = differing_pixels(&left, &right);
    assert!(
        parallax > 2000,
        "left and right eyes nearly equal: {parallax}"
    );

    let scene = reference_scene();
    for mode in StereoMode::ALL {
        let c = recipe(mode, false);
        let frames: &[u64] = if mode == StereoMode::FrameSequential {
            &[0, 1]
        } else {
            &[0]
        };
        for &frame in frames {
            let img = render_recipe(gpu, &scene, &c, frame);
            // File names from the mode's serialised (snake_case) name.
            let mode_name = serde_json::to_string(&mode).expect("mode name");
            let mode_name = mode_name.trim_matches('"');
            let name = match mode {
                StereoMode::FrameSequential => format!("{mode_name}_frame{frame}"),
                _ => mode_name.to_owned(),
            };
            check_golden(&name, &img);
            match mode {
                StereoMode::Mono => {
                    assert!(drawn_pixels(&img) > (WIDTH * HEIGHT / 20) as usize);
                    // The centre eye sits between the two eyes: its image differs from both.
                    assert!(differing_pixels(&img, &left) > 500);
                    assert!(differing_pixels(&img, &right) > 500);
                }
                StereoMode::SideBySideFull => {
                    assert_eq!((img.width, img.height), (2 * WIDTH, HEIGHT));
                    assert_same(
                        &crop(&img, 0, 0, WIDTH, HEIGHT),
                        &left,
                        "left half = left eye",
                    );
                    assert_same(&crop(&img, WIDTH, 0, WIDTH, HEIGHT), &right, "right half");
                }
                StereoMode::SideBySideHalf => {
                    let l = crop(&img, 0, 0, WIDTH / 2, HEIGHT);
                    let r = crop(&img, WIDTH / 2, 0, WIDTH / 2, HEIGHT);
                    assert!(drawn_pixels(&l) > 2000 && drawn_pixels(&r) > 2000);
                    assert!(differing_pixels(&l, &r) > 500, "halves show parallax");
                }
                StereoMode::TopBottom => {
                    let t = crop(&img, 0, 0, WIDTH, HEIGHT / 2);
                    let b = crop(&img, 0, HEIGHT / 2, WIDTH, HEIGHT / 2);
                    assert!(drawn_pixels(&t) > 2000 && drawn_pixels(&b) > 2000);
                    assert!(differing_pixels(&t, &b) > 500, "halves show parallax");
                }
                StereoMode::AnaglyphRedCyan => {
                    assert_same_bytes(&channel(&img, 0), &channel(&left, 0), "red = left eye");
                    assert_same_bytes(&channel(&img, 1), &channel(&right, 1), "green = right");
                    assert_same_bytes(&channel(&img, 2), &channel(&right, 2), "blue = right");
                }
                StereoMode::RowInterleaved => {
                    for y in 0..HEIGHT {
                        let expected = if y % 2 == 0 { &left } else { &right };
                        assert_same_bytes(row(&img, y), row(expected, y), &format!("row {y}"));
                    }
                }
                StereoMode::FrameSequential => {
                    let expected = if frame == 0 { &left } else { &right };
                    assert_same(&img, expected, &format!("frame {frame}"));
                }
            }
        }
    }

    // Swapping the eyes puts the right eye's view in the left slot (red channel, even rows).
    let img = render_recipe(gpu, &scene, &recipe(StereoMode::AnaglyphRedCyan, true), 0);
    assert_same_bytes(&channel(&img, 0), &channel(&right, 0), "swapped red");
    assert_same_bytes(&channel(&img, 1), &channel(&left, 1), "swapped green");
    let img = render_recipe(gpu, &scene, &recipe(StereoMode::RowInterleaved, true), 0);
    assert_same_bytes(row(&img, 0), row(&right, 0), "swapped row 0");
    assert_same_bytes(row(&img, 1), row(&left, 1), "swapped row 1");
}

#[test]
fn layers_can_be_hidden() {
    let Some(gpu) = gpu() else { return };
    let views = reference_views();
    let pass = DrawPass::full(
        views.center.clip_from_world,
        views.center.position_m,
        WIDTH,
        HEIGHT,
    );
    let all = render_single(gpu, &reference_scene(), pass);
    let mut scene = reference_scene();
    scene.layers.skin = false;
    scene.layers.floor_grid = false;
    let fewer = render_single(gpu, &scene, pass);
    assert!(differing_pixels(&all, &fewer) > 1000);
    scene.layers = leman::render::Layers {
        skin: false,
        muscles: false,
        bones: false,
        skeleton: false,
        springs: false,
        fat: false,
        wand: false,
        cursor: false,
        screen_border: false,
        floor_grid: false,
    };
    let none = render_single(gpu, &scene, pass);
    assert_eq!(
        drawn_pixels(&none),
        0,
        "every layer off leaves the background"
    );
}

#[test]
fn nan_vertex_does_not_reach_the_gpu() {
    let Some(gpu) = gpu() else { return };
    let views = reference_views();
    let pass = DrawPass::full(
        views.center.clip_from_world,
        views.center.position_m,
        WIDTH,
        HEIGHT,
    );
    let mut scene = reference_scene();
    let skin = scene.skin.as_mut().expect("skin");
    let bad = 40u32;
    skin.mesh.positions[bad as usize] = Vec3::new(f32::NAN, 0.0, f32::INFINITY);
    // What must be drawn instead: the same mesh without the triangles that use the bad vertex.
    let mut expected_scene = scene.clone();
    let expected_skin = expected_scene.skin.as_mut().expect("skin");
    let kept: Vec<u32> = expected_skin
        .mesh
        .indices
        .chunks(3)
        .filter(|t| !t.contains(&bad))
        .flatten()
        .copied()
        .collect();
    let dropped = (expected_skin.mesh.indices.len() - kept.len()) / 3;
    expected_skin.mesh.indices = kept;
    expected_skin.mesh.positions[bad as usize] = Vec3::ZERO;

    let mut r = Renderer::new(&gpu.device, &gpu.queue, RendererOptions::default()).expect("r");
    let target = r.create_target(WIDTH, HEIGHT).expect("target");
    let report = r.render(&target, &scene, &[pass]).expect("draw");
    assert_eq!(report.sanitized.non_finite_vertices, 1);
    assert_eq!(report.sanitized.dropped_triangles, dropped);
    let with_nan = r.read_image(&target).expect("read");
    let clean = render_single(gpu, &expected_scene, pass);
    assert_same(&with_nan, &clean, "NaN vertex left out");
    // A non-finite eye is refused rather than drawn.
    let mut bad_pass = pass;
    bad_pass.clip_from_world.x_axis.x = f32::NAN;
    assert!(r.render(&target, &scene, &[bad_pass]).is_err());
}

#[test]
fn msaa_changes_only_edges() {
    let Some(gpu) = gpu() else { return };
    let views = reference_views();
    let pass = DrawPass::full(
        views.center.clip_from_world,
        views.center.position_m,
        WIDTH,
        HEIGHT,
    );
    let plain = render_single(gpu, &reference_scene(), pass);
    let options = RendererOptions {
        msaa_samples: 4,
        ..RendererOptions::default()
    };
    let mut r = Renderer::new(&gpu.device, &gpu.queue, options).expect("msaa renderer");
    let target = r.create_target(WIDTH, HEIGHT).expect("target");
    r.render(&target, &reference_scene(), &[pass])
        .expect("draw");
    let smooth = r.read_image(&target).expect("read");
    std::fs::create_dir_all(failure_dir()).expect("dir");
    let _ = smooth.save_png(&failure_dir().join("msaa4_mono.png"));
    // Every changed pixel lies on an edge of the aliased image: some pixel within one step of
    // it differs from it there (flat interiors and background stay the same).
    let is_edge = |x: u32, y: u32| {
        let p = plain.pixel(x, y).expect("pixel");
        (-1i32..=1).any(|dy| {
            (-1i32..=1).any(|dx| {
                let (nx, ny) = (x as i32 + dx, y as i32 + dy);
                nx >= 0
                    && ny >= 0
                    && plain
                        .pixel(nx as u32, ny as u32)
                        .is_some_and(|q| q.iter().zip(&p).any(|(a, b)| a.abs_diff(*b) > 2))
            })
        })
    };
    let mut changed = 0;
    let mut changed_inside = 0;
    for y in 0..HEIGHT {
        for x in 0..WIDTH {
            let (a, b) = (
                plain.pixel(x, y).expect("a"),
                smooth.pixel(x, y).expect("b"),
            );
            if a.iter()
                .zip(&b)
                .any(|(u, v)| u.abs_diff(*v) > CHANNEL_TOLERANCE)
            {
                changed += 1;
                if !is_edge(x, y) {
                    changed_inside += 1;
                }
            }
        }
    }
    assert!(changed > 100, "MSAA changed only {changed} pixels");
    assert_eq!(changed_inside, 0, "MSAA changed pixels away from edges");
    let bad = RendererOptions {
        msaa_samples: 3,
        ..RendererOptions::default()
    };
    assert!(Renderer::new(&gpu.device, &gpu.queue, bad).is_err());
}

/// On Vulkan the image egui is shown is the target itself; GL, which cannot reinterpret a
/// texture's format, shows a copy that every draw refreshes. Run on GL when the machine has it
/// (Mesa llvmpipe through EGL; a loud skip otherwise, whatever `LEMAN_REQUIRE_GPU` says, as
/// GL is the fallback and not the renderer's main path): the target shows a copy, the copy
/// holds exactly the drawn bytes after each of two different draws (the two eyes), and the
/// left eye matches its golden within the other backends' tolerance.
#[test]
fn gl_shows_a_copy_that_every_draw_refreshes() {
    if let Some(gpu) = gpu() {
        let r = Renderer::new(&gpu.device, &gpu.queue, RendererOptions::default()).expect("r");
        let target = r.create_target(WIDTH, HEIGHT).expect("target");
        assert_eq!(
            target.shows_a_copy(),
            gpu.summary.backend == wgpu::Backend::Gl,
            "{}",
            gpu.summary
        );
    }
    private_runtime_dir();
    let gl = match GpuContext::new_headless_on(wgpu::Backends::GL, AdapterPreference::PreferCpu) {
        Ok(gl) => gl,
        Err(e) => {
            say_skipped(&format!("gl_shows_a_copy_that_every_draw_refreshes: {e}"));
            return;
        }
    };
    eprintln!("GL test on: {}", gl.summary);
    let mut r = Renderer::new(&gl.device, &gl.queue, RendererOptions::default()).expect("r");
    let target = r.create_target(WIDTH, HEIGHT).expect("target");
    assert!(target.shows_a_copy());
    let views = reference_views();
    let mut drawn = Vec::new();
    for view in [&views.left, &views.right] {
        let pass = DrawPass::full(view.clip_from_world, view.position_m, WIDTH, HEIGHT);
        r.render(&target, &reference_scene(), &[pass])
            .expect("draw");
        let image = r.read_image(&target).expect("read");
        let shown = r.read_shown_image(&target).expect("read shown");
        assert!(image.pixels == shown.pixels, "the shown copy is stale");
        drawn.push(image);
    }
    assert!(
        differing_pixels(&drawn[0], &drawn[1]) > 2000,
        "the two eyes drew nearly the same image, so the copy's refresh is not shown"
    );
    check_golden_on(gl.summary.backend, "eye_left", &drawn[0]);
}
