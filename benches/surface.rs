//! The LEMAN surface simulation on the paper's 1024-point torso (example `torso`, 32×32 skin,
//! 26 spheres, 12 superellipsoids, 2 cylinders), mid-motion:
//! - `force_evaluation`: elastic (stretch) + tissue + gravity + damping accelerations, once;
//! - `constraints`: one non-penetration pass (with its neighbourhood re-checks) on the state;
//! - `verlet_step`: one whole adaptive Verlet step attempt (skeleton, forces, guard,
//!   constraints, commit);
//! - `torso_16384/verlet_step`: the same on a 128×128 skin;
//! - `tube_1024/…`, `tube_16384/…`: the non-constraint work alone on a synthetic tube (see
//!   `mod tube`): position forces, velocity forces, the guard's scan, one Verlet proposal.
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
    targets = surface, tube_benches
}
criterion_main!(benches);

/// A synthetic M×N tube (radius 0.1 m, 0.6 m long) with the torso's kind of materials: one
/// tissue spring per free point (half of them taut), damping, gravity; no constraints. It
/// measures the non-constraint work of a step on its own: forces, the Verlet passes, the guard.
mod tube {
    use glam::Vec3;
    use leman::sim::ode::SecondOrderSystem;
    use leman::sim::surface::forces::{
        self, ForceInput, ForceScratch, Materials, Springs, StepKinematics,
    };

    pub struct Tube {
        pub m: usize,
        pub n: usize,
        pub materials: Materials,
        pub springs: Springs,
        pub kin: StepKinematics,
        pub scratch: ForceScratch,
        pub x: Vec<f32>,
        pub v: Vec<f32>,
    }

    impl Tube {
        pub fn new(m: usize, n: usize) -> Self {
            let total = m * n;
            let free = m * (n - 2);
            let at = |i: usize, j: usize| {
                let th = i as f32 / m as f32 * std::f32::consts::TAU;
                let wobble = 1.0 + 0.05 * (3.0 * th).sin() * (j as f32 * 0.4).cos();
                Vec3::new(
                    0.1 * wobble * th.cos(),
                    0.6 * j as f32 / (n - 1) as f32,
                    0.1 * th.sin(),
                )
            };
            let mut x = vec![0.0; 3 * free];
            let mut v = vec![0.0; 3 * free];
            for f in 0..free {
                let p = at(f % m, f / m + 1);
                x[f] = p.x;
                x[free + f] = p.y;
                x[2 * free + f] = p.z;
                v[f] = 0.05 * (f as f32 * 0.7).sin();
                v[free + f] = 0.05 * (f as f32 * 0.3).cos();
            }
            let mut rings = [vec![0.0; 2 * m], vec![0.0; 2 * m], vec![0.0; 2 * m]];
            for i in 0..m {
                for (k, j) in [(i, 0), (m + i, n - 1)] {
                    let p = at(i, j);
                    rings[0][k] = p.x;
                    rings[1][k] = p.y;
                    rings[2][k] = p.z;
                }
            }
            // Rest metric: 90 % of the initial one (the skin is under slight tension).
            let (h1, h2) = (1.0 / m as f32, 1.0 / (n - 1) as f32);
            let mut rest = [vec![0.0; total], vec![0.0; total], vec![0.0; total]];
            for j in 0..n {
                for i in 0..m {
                    let k = j * m + i;
                    let a1 = (at(i + 1, j) - at(i, j)) / h1;
                    let a2 = (at(i, (j + 1).min(n - 1)) - at(i, j)) / h2;
                    rest[0][k] = 0.9 * a1.dot(a1);
                    rest[1][k] = 0.9 * a1.dot(a2);
                    rest[2][k] = 0.9 * a2.dot(a2);
                }
            }
            let mass = vec![2.0 / free as f32; free];
            let materials = Materials {
                eta: [vec![40.0; total], vec![20.0; total], vec![40.0; total]],
                rest_metric: rest,
                xi: [vec![0.0; total], vec![0.0; total], vec![0.0; total]],
                rest_curvature: [vec![0.0; total], vec![0.0; total], vec![0.0; total]],
                has_bending: false,
                inv_mass: mass.iter().map(|m| 1.0 / m).collect(),
                damping_per_mass: mass.iter().map(|m| 0.002 / m).collect(),
                damping: vec![0.002; free],
                mass_kg: mass,
                fat_m: vec![0.01; free],
                gravity: Vec3::new(0.0, -9.81, 0.0),
            };
            // Anchors 1 cm inside each point; rest lengths alternate slack/taut.
            let mut anchors = [vec![0.0; free], vec![0.0; free], vec![0.0; free]];
            for f in 0..free {
                let p = Vec3::new(x[f], x[free + f], x[2 * free + f]);
                let a = p - 0.01 * Vec3::new(p.x, 0.0, p.z).normalize_or_zero();
                anchors[0][f] = a.x;
                anchors[1][f] = a.y;
                anchors[2][f] = a.z;
            }
            let springs = Springs {
                point: (0..free as u32).collect(),
                source: (0..free as u32).collect(),
                ks: vec![5.0; free],
                kd: vec![0.05; free],
                rest_m: (0..free)
                    .map(|f| if f % 2 == 0 { 0.005 } else { 0.02 })
                    .collect(),
                shape: vec![0; free],
                anchor_rest_m: vec![Vec3::ZERO; free],
            };
            let kin = StepKinematics {
                t0_s: 0.0,
                h_s: 0.004,
                rings_start: rings.clone(),
                rings_end: rings,
                anchors_start: anchors.clone(),
                anchors_end: anchors,
            };
            Self {
                m,
                n,
                materials,
                springs,
                kin,
                scratch: ForceScratch::default(),
                x,
                v,
            }
        }

        pub fn input(&self) -> ForceInput<'_> {
            ForceInput {
                around: self.m,
                along: self.n,
                materials: &self.materials,
                springs: &self.springs,
                kin: &self.kin,
            }
        }
    }

    /// The tube as the integrators see it.
    pub struct System<'a> {
        pub input: ForceInput<'a>,
        pub scratch: &'a mut ForceScratch,
    }

    impl SecondOrderSystem for System<'_> {
        fn dofs(&self) -> usize {
            3 * self.input.around * (self.input.along - 2)
        }
        fn position_accel(&mut self, t_s: f64, x: &[f32], a: &mut [f32]) {
            forces::position_accel(&self.input, self.scratch, t_s, x, a);
        }
        fn add_velocity_accel(&mut self, _t_s: f64, _x: &[f32], v: &[f32], a: &mut [f32]) {
            forces::add_velocity_accel(&self.input, self.scratch, v, a);
        }
        fn velocity_accel_from(
            &mut self,
            _t_s: f64,
            _x: &[f32],
            v: &[f32],
            a_pos: &[f32],
            a: &mut [f32],
        ) {
            // The model's own path (the copy of the position part fused into the damping pass).
            forces::velocity_accel_from(&self.input, self.scratch, v, a_pos, a);
        }
    }
}

fn tube_benches(c: &mut Criterion) {
    use leman::sim::ode::{Integrator, Tolerances};
    use leman::sim::surface::forces;
    for (m, n) in [(32usize, 32usize), (128, 128)] {
        let name = format!("tube_{}", m * n);
        let mut t = tube::Tube::new(m, n);
        let mut a = vec![0.0f32; t.x.len()];
        let (x, v) = (t.x.clone(), t.v.clone());
        let mut scratch = std::mem::take(&mut t.scratch);
        c.bench_function(&format!("{name}/position_accel"), |b| {
            b.iter(|| {
                forces::position_accel(&t.input(), &mut scratch, 0.002, black_box(&x), &mut a);
                black_box(a[0])
            })
        });
        c.bench_function(&format!("{name}/velocity_accel"), |b| {
            b.iter(|| {
                forces::add_velocity_accel(&t.input(), &scratch, black_box(&v), &mut a);
                black_box(a[0])
            })
        });
        c.bench_function(&format!("{name}/guard_scan"), |b| {
            b.iter(|| black_box(forces::guard_scan(&t.materials, black_box(&x), &v, &v)))
        });
        // One Verlet proposal of 4 ms (forces, fixed-point iterations, error estimate): the
        // whole non-constraint part of a step but the skeleton and the guard.
        let mut integ = Integrator::new(IntegratorKind::Verlet, Tolerances::default());
        let (mut xn, mut vn) = (vec![0.0f32; x.len()], vec![0.0f32; x.len()]);
        let mut iterations = 0u64;
        let mut proposals = 0u64;
        c.bench_function(&format!("{name}/verlet_propose"), |b| {
            b.iter(|| {
                let mut sys = tube::System {
                    input: t.input(),
                    scratch: &mut scratch,
                };
                let p = integ.propose(&mut sys, 0.0, 0.004, &x, &v, &mut xn, &mut vn);
                iterations += u64::from(p.velocity_evals);
                proposals += 1;
                black_box(p)
            })
        });
        eprintln!(
            "{name}/verlet_propose: {:.2} velocity evaluations per proposal",
            iterations as f64 / proposals.max(1) as f64
        );
    }
}
