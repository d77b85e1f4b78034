//! Frame time of the renderer and its parts, for the paper's 1024-point torso (example
//! character `torso` at 32 × 32 skin points, 40 shapes, skeleton, floor grid, screen border) in
//! side-by-side (half) stereo at 1280 × 720, on whatever adapter `GpuContext::new_headless`
//! picks (a CPU adapter, i.e. lavapipe, first). Parts:
//! - `build_geometry`: scene to flat vertex arrays (CPU);
//! - `prepare`: build + upload to GPU buffers;
//! - `draw_and_wait`: encode both eye passes, submit, wait for the GPU;
//! - `frame`: prepare + draw + wait (what the frame loop pays);
//! - `frame_with_readback`: frame + copying the image back (offscreen/replay PNG path);
//! - `draw_and_wait_640x360`: the same at a quarter of the pixels (how much is fill);
//! - `draw_and_wait_skin_only`: without the 40 shapes (how much is their geometry).
//!
//! Run: `cargo bench --bench render` (criterion reports medians in its estimates). The bench
//! also writes the frame it measured to `target/render_bench_torso_sbs.png`.

use std::path::PathBuf;

use criterion::{Criterion, criterion_group, criterion_main};
use glam::Vec3;
use leman::calibration::{CalibrationProfile, ScreenRect};
use leman::pose::Pose;
use leman::render::batch::FrameGeometry;
use leman::render::reference::torso_scene;
use leman::render::{GpuContext, Renderer, RendererOptions, Scene};
use leman::stereo::{
    Composition, OutputSettings, StereoMode, ViewSettings, compose, eye_views_for,
};

const WIDTH: u32 = 1280;
const HEIGHT: u32 = 720;

/// A calibrated window framing the scene's skin (16:9), the viewer 0.6 m in front of it, and
/// the side-by-side recipe for it.
fn framing(scene: &Scene) -> Composition {
    let points = scene
        .skin
        .as_ref()
        .map(|s| s.mesh.positions.clone())
        .unwrap_or_default();
    let (lo, hi) = points.iter().fold(
        (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let centre = (lo + hi) * 0.5;
    let height_m = ((hi.y - lo.y) * 1.3)
        .max((hi.x - lo.x) * 1.3 * 9.0 / 16.0)
        .max(0.05);
    let window = ScreenRect::from_center(
        Vec3::new(centre.x, centre.y, hi.z),
        Vec3::X,
        Vec3::Y,
        height_m * 16.0 / 9.0,
        height_m,
    )
    .expect("window");
    let profile = CalibrationProfile::default();
    let head = Pose::from_translation(Vec3::new(centre.x, centre.y, hi.z + 0.6));
    let views = eye_views_for(
        &window,
        &profile.head_eyes,
        profile.baseline,
        &head,
        &ViewSettings::default(),
    )
    .expect("views");
    compose(
        &views,
        &OutputSettings {
            mode: StereoMode::SideBySideHalf,
            swap_eyes: false,
        },
        [WIDTH, HEIGHT],
    )
}

fn bench_render(c: &mut Criterion) {
    let gpu = match GpuContext::new_headless() {
        Ok(g) => g,
        Err(e) => {
            eprintln!("*** SKIPPED render bench: {e} ***");
            return;
        }
    };
    eprintln!("render bench on {}", gpu.summary);
    let scene = torso_scene().expect("torso example");
    let recipe = framing(&scene);
    let mut renderer =
        Renderer::new(&gpu.device, &gpu.queue, RendererOptions::default()).expect("renderer");
    let target = renderer.create_target(WIDTH, HEIGHT).expect("target");

    // One frame to look at, and its size.
    renderer.prepare(&scene);
    let report = renderer
        .draw_composition(&target, &recipe, 0)
        .expect("draw");
    let image = renderer.read_image(&target).expect("read");
    let out = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/render_bench_torso_sbs.png");
    if image.save_png(&out).is_ok() {
        eprintln!("frame written to {}", out.display());
    }
    eprintln!(
        "frame: {} passes, {} triangles and {} line segments per pass",
        report.passes, report.triangles, report.segments
    );

    let mut group = c.benchmark_group("torso_1024_sbs_1280x720");
    group.sample_size(30);
    group.bench_function("build_geometry", |b| {
        b.iter(|| FrameGeometry::build(std::hint::black_box(&scene)))
    });
    group.bench_function("prepare", |b| b.iter(|| renderer.prepare(&scene)));
    renderer.prepare(&scene);
    group.bench_function("draw_and_wait", |b| {
        b.iter(|| {
            renderer
                .draw_composition(&target, &recipe, 0)
                .expect("draw");
            renderer.wait_idle().expect("wait");
        })
    });
    group.bench_function("frame", |b| {
        b.iter(|| {
            renderer.prepare(&scene);
            renderer
                .draw_composition(&target, &recipe, 0)
                .expect("draw");
            renderer.wait_idle().expect("wait");
        })
    });
    group.bench_function("frame_with_readback", |b| {
        b.iter(|| {
            renderer.prepare(&scene);
            renderer
                .draw_composition(&target, &recipe, 0)
                .expect("draw");
            renderer.read_image(&target).expect("read")
        })
    });
    // Where the GPU time goes: the same frame at a quarter of the pixels (fill cost), and
    // with only the skin (geometry cost of the 40 shapes).
    let small = renderer
        .create_target(WIDTH / 2, HEIGHT / 2)
        .expect("small target");
    let small_recipe = leman::stereo::Composition {
        output_size_px: [WIDTH / 2, HEIGHT / 2],
        passes: recipe
            .passes
            .iter()
            .map(|p| leman::stereo::EyePass {
                viewport: leman::stereo::ViewportPx {
                    x: p.viewport.x / 2,
                    y: p.viewport.y / 2,
                    width: p.viewport.width / 2,
                    height: p.viewport.height / 2,
                },
                ..*p
            })
            .collect(),
        ..recipe.clone()
    };
    renderer.prepare(&scene);
    group.bench_function("draw_and_wait_640x360", |b| {
        b.iter(|| {
            renderer
                .draw_composition(&small, &small_recipe, 0)
                .expect("draw");
            renderer.wait_idle().expect("wait");
        })
    });
    let mut skin_only = scene.clone();
    skin_only.layers.muscles = false;
    skin_only.layers.bones = false;
    renderer.prepare(&skin_only);
    group.bench_function("draw_and_wait_skin_only", |b| {
        b.iter(|| {
            renderer
                .draw_composition(&target, &recipe, 0)
                .expect("draw");
            renderer.wait_idle().expect("wait");
        })
    });
    group.finish();
}

criterion_group!(benches, bench_render);
criterion_main!(benches);
