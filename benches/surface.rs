//! The LEMAN surface simulation on the paper's 1024-point torso (example `torso`, 32×32 skin,
//! 26 spheres, 12 superellipsoids, 2 cylinders), mid-motion:
//! - `force_evaluation`: elastic (stretch) + tissue + gravity + damping accelerations, once;
//! - `constraints`: one non-penetration pass (with its neighbourhood re-checks) on the state;
//! - `verlet_step`: one whole adaptive Verlet step attempt (skeleton, forces, guard,
//!   constraints, commit);
//! - `verlet_step_128x128`: the same on a 128×128 skin.
//!
//! Run: `cargo bench --bench surface` (criterion prints the median in its estimates).

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use leman::character::examples;
use leman::sim::surface::SurfaceModel;
use leman::sim::{DeformationModel, IntegratorKind, MaxAttempts, MotionPoses};

fn torso(res: u32) -> (SurfaceModel, leman::character::Motion) {
    let c = examples::build("torso", res, res).expect("torso example");
    let motion = c.motions[0].clone();
    let mut m = SurfaceModel::new(c, IntegratorKind::Verlet).expect("torso simulates");
    // Mid-motion, with the skin settled on the muscles.
    m.advance(
        0.5,
        &mut MotionPoses(&motion),
        &mut leman::sim::Unlimited,
        None,
    );
    (m, motion)
}

fn surface(c: &mut Criterion) {
    let (mut m, motion) = torso(32);
    let mut poses = MotionPoses(&motion);
    c.bench_function("torso_1024/force_evaluation", |b| {
        b.iter(|| black_box(m.evaluate_forces_once(&mut poses)))
    });
    c.bench_function("torso_1024/constraints", |b| {
        b.iter(|| black_box(m.enforce_constraints_once(&mut poses, 0.005)))
    });
    c.bench_function("torso_1024/verlet_step", |b| {
        b.iter(|| {
            let t = m.time_s() + 0.05;
            black_box(m.advance(t, &mut poses, &mut MaxAttempts(1), None))
        })
    });
    let (mut big, motion) = torso(128);
    let mut poses = MotionPoses(&motion);
    c.bench_function("torso_16384/verlet_step", |b| {
        b.iter(|| {
            let t = big.time_s() + 0.05;
            black_box(big.advance(t, &mut poses, &mut MaxAttempts(1), None))
        })
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30);
    targets = surface
}
criterion_main!(benches);
