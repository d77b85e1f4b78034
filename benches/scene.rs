//! Building one frame's scene on the CPU (`app::scene::build_scene`) for the paper's torso
//! (example `torso`, 32×32 skin, 40 shapes) 0.7 s into its motion: the skin refined for
//! display (Catmull-Rom, 64 × 63 points) and kept outside the muscles
//! (`app::skin_display::keep_outside`), the shapes deformed and placed, the skeleton lines.
//! The frame loop pays this once per frame.
//! - `torso_bent/build_scene`: the whole scene;
//! - `torso_bent/keep_outside`: the display push-out alone on the refined skin.
//!
//! Run: `cargo bench --bench scene` (criterion prints the median in its estimates).

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use glam::Vec3;
use leman::app::scene::{SceneInputs, ShapeMeshes, build_scene};
use leman::app::skin_display::{keep_outside, resample_field};
use leman::character::{Posture, SkeletonPose, examples};
use leman::pose::Pose;
use leman::render::scene::Layers;
use leman::render::subdivide;
use leman::sim::surface::SurfaceModel;
use leman::sim::{DeformationModel, IntegratorKind, MotionPoses, SurfaceMesh, Unlimited};

fn scene(c: &mut Criterion) {
    let t = 0.7;
    let character = examples::build("torso", 32, 32).expect("torso example");
    let motion = character.motions[0].clone();
    let mut model = SurfaceModel::new(character.clone(), IntegratorKind::Verlet).expect("sim");
    model.advance(t, &mut MotionPoses(&motion), &mut Unlimited, None);
    let mut surface = SurfaceMesh::default();
    model.surface_mesh_into(&mut surface);
    let mut posture = Posture::neutral(&character.skeleton);
    motion.posture_at_into(t as f32, &mut posture);
    let mut pose = SkeletonPose::default();
    character
        .skeleton
        .forward_kinematics_into(&posture, &mut pose);
    let shape_meshes = ShapeMeshes::new(&character);
    let (m, n) = model.resolution();
    let inputs = SceneInputs {
        character: &character,
        shape_meshes: &shape_meshes,
        posture: &posture,
        skeleton_pose: &pose,
        time_s: t as f32,
        skin_positions_world: &surface.positions_m,
        skin_grid: (m, n),
        vehicle_from_world: Pose::IDENTITY,
        wand_physical: None,
        screen_corners: [Vec3::ZERO; 4],
        layers: Layers::default(),
        skin_opacity: 1.0,
    };
    c.bench_function("torso_bent/build_scene", |b| {
        b.iter(|| black_box(build_scene(&inputs)))
    });

    let level = subdivide::display_level(m);
    let (rm, rn) = subdivide::refined_size(m, n, level);
    let (rm, rn) = (rm as usize, rn as usize);
    let refined = subdivide::refine_skin_grid(&surface.positions_m, m, n, level);
    let fat = resample_field(&character.skin.fat_m, 32, 32, rm, rn);
    let mut shapes = Vec::new();
    character.shape_instances_into(&posture, &pose, t as f32, &mut shapes);
    c.bench_function("torso_bent/keep_outside", |b| {
        b.iter(|| {
            let mut points = refined.clone();
            black_box(keep_outside(&mut points, rm, rn, &fat, &shapes))
        })
    });
}

criterion_group!(benches, scene);
criterion_main!(benches);
