//! Building one frame's scene on the CPU (`app::scene::build_scene`) for the paper's torso
//! (example `torso`, 32×32 skin, 40 shapes) 0.7 s into its motion (`app::scene::BentTorso`):
//! the skin refined for display (Catmull-Rom, 64 × 63 points) and kept outside the muscles
//! (`app::skin_display::keep_outside`), the shapes deformed and placed, the skeleton lines.
//! The frame loop pays this once per frame.
//! - `torso_bent/build_scene`: the whole scene;
//! - `torso_bent/keep_outside`: the display push-out alone on the refined skin.
//!
//! Run: `cargo bench --bench scene` (criterion prints the median in its estimates).

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use leman::app::scene::{BentTorso, build_scene};
use leman::app::skin_display::keep_outside;
use leman::character::resample::resample_field;
use leman::render::subdivide;

fn scene(c: &mut Criterion) {
    let torso = BentTorso::new().expect("torso example");
    let inputs = torso.inputs();
    c.bench_function("torso_bent/build_scene", |b| {
        b.iter(|| black_box(build_scene(&inputs)))
    });

    let (m, n) = torso.skin_grid;
    let level = subdivide::display_level(m);
    let (rm, rn) = subdivide::refined_size(m, n, level);
    let refined = subdivide::refine_skin_grid(&torso.skin_positions_world, m, n, level);
    let skin = &torso.character.skin;
    let fat = resample_field(&skin.fat_m, skin.around, skin.along, rm, rn);
    let (rm, rn) = (rm as usize, rn as usize);
    let shapes = torso.shapes();
    c.bench_function("torso_bent/keep_outside", |b| {
        b.iter(|| {
            let mut points = refined.clone();
            black_box(keep_outside(&mut points, rm, rn, &fat, &shapes))
        })
    });
}

criterion_group!(benches, scene);
criterion_main!(benches);
