//! Placing the connective tissue's anchors in the world for a step (LEMAN 4.1.2: the far end of
//! each tissue spring is a point fixed on a muscle, kept in the muscle's rest space so that it
//! follows the skeleton and the muscle's deformations).
//!
//! Placing them one by one (`ShapeInstance::rest_point_to_world`) cost about 60 instructions
//! per anchor and step attempt, with library sines for twisted and bent muscles: 1.1 M per
//! attempt on a 128×128 torso. Here the anchors are grouped by shape in structure-of-arrays
//! form, and each shape's deformations and transform run as one vectorised loop each over its
//! group, with the fast sine of [`super::fastmath`] (absolute error about 1e-7, against anchors
//! a few centimetres from their shape's origin).

#![allow(clippy::needless_range_loop)] // index loops over parallel SoA arrays read best as they are

use glam::Affine3A;

use super::fastmath::sin_cos;
use super::forces::Springs;
use crate::character::shape::{MIN_CURVATURE_PER_M, MIN_TAPER_SCALE};
use crate::character::{Resolved, ShapeInstance};

/// The springs' anchors grouped by the shape that carries them.
#[derive(Debug, Clone, Default)]
pub struct AnchorTable {
    /// Spring indices, shape by shape: shape `s` carries `order[offsets[s]..offsets[s + 1]]`.
    /// Springs on a shape index the character does not have come last (placed at the origin).
    order: Vec<u32>,
    offsets: Vec<u32>,
    /// Each anchor in its shape's rest space (metres), in `order`'s order.
    rest: [Vec<f32>; 3],
    /// `order` cut into runs of consecutive springs: `(first index into order, first spring,
    /// length)`; shape `s`'s runs are `runs[run_offsets[s]..run_offsets[s + 1]]`.
    runs: Vec<[u32; 3]>,
    run_offsets: Vec<u32>,
}

impl AnchorTable {
    /// Groups the anchors of `springs` by shape, for characters with `shape_count` shapes.
    pub fn new(springs: &Springs, shape_count: usize) -> Self {
        let n = springs.shape.len().min(springs.anchor_rest_m.len());
        // Counting sort: one bucket per shape and one for out-of-range shapes.
        let bucket = |q: usize| (springs.shape[q] as usize).min(shape_count);
        let mut offsets = vec![0u32; shape_count + 2];
        for q in 0..n {
            offsets[bucket(q) + 1] += 1;
        }
        for s in 0..=shape_count {
            offsets[s + 1] += offsets[s];
        }
        let mut next = offsets.clone();
        let mut order = vec![0u32; n];
        let mut rest = [vec![0.0; n], vec![0.0; n], vec![0.0; n]];
        for q in 0..n {
            let slot = &mut next[bucket(q)];
            let i = *slot as usize;
            *slot += 1;
            order[i] = q as u32;
            let p = springs.anchor_rest_m[q];
            (rest[0][i], rest[1][i], rest[2][i]) = (p.x, p.y, p.z);
        }
        // Runs of consecutive springs within each shape's group (the springs follow the skin
        // points, so a shape's anchors come in stretches of neighbouring points).
        let mut runs: Vec<[u32; 3]> = Vec::new();
        let mut run_offsets = vec![0u32; offsets.len()];
        for s in 0..offsets.len() - 1 {
            let (a, b) = (offsets[s] as usize, offsets[s + 1] as usize);
            let mut i = a;
            while i < b {
                let mut j = i + 1;
                while j < b && order[j] == order[j - 1] + 1 {
                    j += 1;
                }
                runs.push([i as u32, order[i], (j - i) as u32]);
                i = j;
            }
            run_offsets[s + 1] = runs.len() as u32;
        }
        Self {
            order,
            offsets,
            rest,
            runs,
            run_offsets,
        }
    }

    /// Number of anchors.
    fn len(&self) -> usize {
        self.order.len()
    }

    /// Writes every anchor's world position for the shape instances `shapes` into `out` (SoA
    /// by spring index, resized to the spring count), metres. Anchors on a shape that `shapes`
    /// does not have are placed at the origin. `scratch` is reused between calls.
    pub fn place(
        &self,
        shapes: &[ShapeInstance],
        out: &mut [Vec<f32>; 3],
        scratch: &mut [Vec<f32>; 3],
    ) {
        let n = self.len();
        for c in out.iter_mut() {
            c.resize(n, 0.0);
        }
        let groups = self.offsets.len().saturating_sub(2).min(shapes.len());
        // Anchors on shapes that `shapes` does not have: the origin (every other entry of `out`
        // is written below).
        let placed = self.offsets.get(groups).map_or(0, |&o| o as usize);
        for &q in &self.order[placed..] {
            for c in out.iter_mut() {
                c[q as usize] = 0.0;
            }
        }
        for (s, shape) in shapes.iter().enumerate().take(groups) {
            let (a, b) = (self.offsets[s] as usize, self.offsets[s + 1] as usize);
            if a == b {
                continue;
            }
            let len = b - a;
            let runs = &self.runs[self.run_offsets[s] as usize..self.run_offsets[s + 1] as usize];
            let [ox, oy, oz] = &mut *out;
            let by_runs = runs.len() * RUN_MIN <= len;
            if by_runs && shape.geometry.deformations().is_empty() {
                // Undeformed: straight from the rest positions into place.
                let [x, y, z] = &self.rest;
                transform_runs(
                    &shape.world_from_shape,
                    &x[a..b],
                    &y[a..b],
                    &z[a..b],
                    a,
                    runs,
                    ox,
                    oy,
                    oz,
                );
                continue;
            }
            for (t, r) in scratch.iter_mut().zip(&self.rest) {
                t.clear();
                t.extend_from_slice(&r[a..b]);
            }
            let [x, y, z] = scratch;
            let (x, y, z) = (&mut x[..len], &mut y[..len], &mut z[..len]);
            for d in shape.geometry.deformations() {
                match *d {
                    Resolved::Taper { rate_per_m } => taper(rate_per_m, x, y, z),
                    Resolved::Twist { rate_rad_per_m } => twist(rate_rad_per_m, x, y, z),
                    Resolved::Bend { curvature_per_m } => {
                        if curvature_per_m.abs() >= MIN_CURVATURE_PER_M {
                            bend(curvature_per_m, x, y)
                        }
                    }
                }
            }
            if by_runs {
                transform_runs(&shape.world_from_shape, x, y, z, a, runs, ox, oy, oz);
                continue;
            }
            // Short runs: transform in place as one vector loop, then scatter point by point.
            transform(&shape.world_from_shape, x, y, z);
            for (&q, ((x, y), z)) in self.order[a..b]
                .iter()
                .zip(x.iter().zip(y.iter()).zip(z.iter()))
            {
                let q = q as usize;
                (ox[q], oy[q], oz[q]) = (*x, *y, *z);
            }
        }
    }
}

/// Shapes whose anchors come in runs of at least this many consecutive springs on average are
/// transformed run by run straight into place; others as one vector loop and then scattered.
const RUN_MIN: usize = 8;

// The deformations rest → deformed as `Resolved::apply`, in place over SoA points.

crate::sim::simd::multiversion! {
    fn taper(rate: f32, x: &mut [f32], y: &[f32], z: &mut [f32]) {
        let n = x.len().min(y.len()).min(z.len());
        let (x, y, z) = (&mut x[..n], &y[..n], &mut z[..n]);
        for i in 0..n {
            let r = (1.0 + rate * y[i]).max(MIN_TAPER_SCALE);
            x[i] *= r;
            z[i] *= r;
        }
    }
}

crate::sim::simd::multiversion! {
    fn twist(w: f32, x: &mut [f32], y: &[f32], z: &mut [f32]) {
        let n = x.len().min(y.len()).min(z.len());
        let (x, y, z) = (&mut x[..n], &y[..n], &mut z[..n]);
        for i in 0..n {
            let (s, c) = sin_cos(w * y[i]);
            let (px, pz) = (x[i], z[i]);
            x[i] = px * c - pz * s;
            z[i] = px * s + pz * c;
        }
    }
}

crate::sim::simd::multiversion! {
    fn bend(k: f32, x: &mut [f32], y: &mut [f32]) {
        let n = x.len().min(y.len());
        let (x, y) = (&mut x[..n], &mut y[..n]);
        let inv_k = 1.0 / k;
        for i in 0..n {
            let theta = k * y[i];
            let (s, c) = sin_cos(theta);
            let half = sin_cos(0.5 * theta).0;
            let px = x[i];
            // (1 − cos θ)/k written without cancellation.
            x[i] = px * c + 2.0 * half * half * inv_k;
            y[i] = (1.0 - k * px) * s * inv_k;
        }
    }
}

crate::sim::simd::multiversion! {
    /// `p ← world_from_shape · p` for every point.
    fn transform(world_from_shape: &Affine3A, x: &mut [f32], y: &mut [f32], z: &mut [f32]) {
        let n = x.len().min(y.len()).min(z.len());
        let (x, y, z) = (&mut x[..n], &mut y[..n], &mut z[..n]);
        let m = world_from_shape.matrix3;
        let (cx, cy, cz) = (m.x_axis, m.y_axis, m.z_axis);
        let o = world_from_shape.translation;
        for i in 0..n {
            let (px, py, pz) = (x[i], y[i], z[i]);
            x[i] = cx.x * px + cy.x * py + cz.x * pz + o.x;
            y[i] = cx.y * px + cy.y * py + cz.y * pz + o.y;
            z[i] = cx.z * px + cy.z * py + cz.z * pz + o.z;
        }
    }
}

crate::sim::simd::multiversion! {
    /// `out[q] ← world_from_shape · p[i]` for the points `p = (x, y, z)` of one shape's group
    /// (starting at index `base` of the table's order) over its `runs` of consecutive springs
    /// `[i + base, q, len]`.
    fn transform_runs(
        world_from_shape: &Affine3A,
        x: &[f32],
        y: &[f32],
        z: &[f32],
        base: usize,
        runs: &[[u32; 3]],
        ox: &mut [f32],
        oy: &mut [f32],
        oz: &mut [f32],
    ) {
        let m = world_from_shape.matrix3;
        let (cx, cy, cz) = (m.x_axis, m.y_axis, m.z_axis);
        let o = world_from_shape.translation;
        use crate::sim::simd::LANES;
        #[inline(always)]
        #[allow(clippy::too_many_arguments)]
        fn one(
            c: [glam::Vec3A; 4],
            px: f32,
            py: f32,
            pz: f32,
            ox: &mut f32,
            oy: &mut f32,
            oz: &mut f32,
        ) {
            let [cx, cy, cz, o] = c;
            *ox = cx.x * px + cy.x * py + cz.x * pz + o.x;
            *oy = cx.y * px + cy.y * py + cz.y * pz + o.y;
            *oz = cx.z * px + cy.z * py + cz.z * pz + o.z;
        }
        let c = [cx, cy, cz, o];
        for run in runs {
            let (i, q, n) = (run[0] as usize - base, run[1] as usize, run[2] as usize);
            let (x, y, z) = (&x[i..i + n], &y[i..i + n], &z[i..i + n]);
            let (ox, oy, oz) = (&mut ox[q..q + n], &mut oy[q..q + n], &mut oz[q..q + n]);
            if n < LANES {
                for k in 0..n {
                    one(c, x[k], y[k], z[k], &mut ox[k], &mut oy[k], &mut oz[k]);
                }
                continue;
            }
            // Blocks of LANES points, the last one ending at the run's end (it may overlap the
            // one before: those points are written twice with the same values).
            let mut k0 = 0;
            loop {
                let k = k0.min(n - LANES);
                let (bx, by, bz) = (&x[k..k + LANES], &y[k..k + LANES], &z[k..k + LANES]);
                let (wx, wy, wz) = (
                    &mut ox[k..k + LANES],
                    &mut oy[k..k + LANES],
                    &mut oz[k..k + LANES],
                );
                for l in 0..LANES {
                    one(c, bx[l], by[l], bz[l], &mut wx[l], &mut wy[l], &mut wz[l]);
                }
                if k + LANES >= n {
                    break;
                }
                k0 += LANES;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;
    use crate::character::examples;
    use crate::character::{Character, Posture, ShapeInstance, SkeletonPose};

    /// The character's shapes 0.7 s into its first motion, where the torso's muscles that
    /// follow joints are tapered, twisted and bent far from rest.
    fn bent_shapes(character: &Character) -> Vec<ShapeInstance> {
        let motion = &character.motions[0];
        let mut posture = Posture::neutral(&character.skeleton);
        motion.posture_at_into(0.7, &mut posture);
        let mut pose = SkeletonPose::default();
        character
            .skeleton
            .forward_kinematics_into(&posture, &mut pose);
        let mut shapes = Vec::new();
        character.shape_instances_into(&posture, &pose, 0.7, &mut shapes);
        shapes
    }

    #[test]
    fn placed_anchors_match_the_shapes_own_mapping_in_a_bent_posture() {
        // The torso has tapered, twisted and bent muscles whose deformations follow joints:
        // take a posture from the middle of its motion, where they are far from rest.
        let character = examples::build("torso", 16, 16).expect("the torso example exists");
        let springs = Springs {
            shape: character.tissue.iter().map(|t| t.shape.0).collect(),
            anchor_rest_m: character.tissue.iter().map(|t| t.anchor_rest_m).collect(),
            ..Default::default()
        };
        // One spring on a shape the character does not have.
        let mut springs = springs;
        springs.shape.push(9999);
        springs.anchor_rest_m.push(Vec3::new(0.1, 0.2, 0.3));
        let table = AnchorTable::new(&springs, character.shapes.len());
        assert_eq!(table.len(), springs.shape.len());
        let shapes = bent_shapes(&character);
        let deformed = shapes
            .iter()
            .filter(|s| !s.geometry.is_undeformed())
            .count();
        assert!(deformed >= 3, "the test needs deformed muscles: {deformed}");
        let (mut out, mut scratch) = (Default::default(), Default::default());
        table.place(&shapes, &mut out, &mut scratch);
        let [ox, oy, oz]: &[Vec<f32>; 3] = &out;
        let mut worst = 0.0f32;
        for (q, (&s, &rest)) in springs.shape.iter().zip(&springs.anchor_rest_m).enumerate() {
            let want = shapes
                .get(s as usize)
                .map_or(Vec3::ZERO, |inst| inst.rest_point_to_world(rest));
            let got = Vec3::new(ox[q], oy[q], oz[q]);
            worst = worst.max((got - want).length());
        }
        assert!(worst < 1e-6, "anchors off by up to {worst} m");
        // Placed again with the last shape missing, its anchors go to the origin (the earlier
        // positions in `out` must not stay).
        let last = shapes.len() - 1;
        table.place(&shapes[..last], &mut out, &mut scratch);
        let on_last: Vec<usize> = (0..springs.shape.len())
            .filter(|&q| springs.shape[q] as usize == last)
            .collect();
        assert!(
            !on_last.is_empty(),
            "the torso's last shape carries anchors"
        );
        for q in on_last {
            assert_eq!([out[0][q], out[1][q], out[2][q]], [0.0; 3], "spring {q}");
        }
    }

    #[test]
    fn anchors_in_long_runs_go_straight_into_place() {
        // Springs whose shapes come in runs of 1 to 40 consecutive springs (placed run by run:
        // short runs point by point, long ones in vector blocks, the last block overlapping),
        // on every shape of the torso, deformed ones included, in a bent posture.
        let character = examples::build("torso", 16, 16).expect("the torso example exists");
        let shape_count = character.shapes.len();
        let lengths = [1usize, 3, 7, 8, 9, 15, 16, 17, 31, 40];
        let mut shape = Vec::new();
        for block in 0..4 * shape_count {
            let len = lengths[block % lengths.len()];
            shape.extend(std::iter::repeat_n((block % shape_count) as u32, len));
        }
        let n = shape.len();
        let springs = Springs {
            shape,
            anchor_rest_m: (0..n)
                .map(|q| {
                    let t = q as f32 * 0.37;
                    Vec3::new(
                        0.03 * t.sin(),
                        0.05 * (0.7 * t).cos(),
                        0.02 * (1.3 * t).sin(),
                    )
                })
                .collect(),
            ..Default::default()
        };
        let table = AnchorTable::new(&springs, shape_count);
        assert!(table.runs.len() * RUN_MIN <= n, "{} runs", table.runs.len());
        let shapes = bent_shapes(&character);
        assert!(shapes.iter().any(|s| !s.geometry.is_undeformed()));
        let (mut out, mut scratch) = (Default::default(), Default::default());
        table.place(&shapes, &mut out, &mut scratch);
        let [ox, oy, oz]: &[Vec<f32>; 3] = &out;
        for (q, (&s, &rest)) in springs.shape.iter().zip(&springs.anchor_rest_m).enumerate() {
            let want = shapes[s as usize].rest_point_to_world(rest);
            let got = Vec3::new(ox[q], oy[q], oz[q]);
            assert!((got - want).length() < 1e-6, "spring {q}: {got} vs {want}");
        }
    }
}
