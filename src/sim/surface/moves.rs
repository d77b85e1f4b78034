//! The last stage of a shape's turn in a constraint pass ([`super::constraints`]): turning the
//! batch's projections (shape frame) into world moves, push directions and the muscle
//! surface's velocity where each point was left (eq. 13's reference), for every entry at once
//! in vectorised passes. Only the rare entries whose batched Newton steps did not converge, and
//! the writes into the pass's per-point arrays, stay point by point (in
//! [`super::constraints`]).
//!
//! The arithmetic is that of the `glam` expressions the per-point code used
//! (`Affine3A::transform_point3`/`transform_vector3`: `((x_axis·a + y_axis·b) + z_axis·c) + t`,
//! `Vec3::length`, component-wise division), in the same order, so the results are the same
//! bits.

#![allow(clippy::too_many_arguments)] // each SoA slice is its own argument (see `sim::simd`)

use glam::Affine3A;

use super::kernels::on_surface;

/// Per-entry results of one shape's batch (structure of arrays, reused between calls).
#[derive(Debug, Clone, Default)]
pub struct MoveBatch {
    /// 1 where the entry's last value and gradient put it on the surface (within the
    /// projection tolerance), else 0.
    pub converged: Vec<u8>,
    /// The move, world, metres.
    pub d: [Vec<f32>; 3],
    /// `|d|`, metres.
    pub len: Vec<f32>,
    /// `d / |d|`, world.
    pub normal: [Vec<f32>; 3],
    /// 1 where the move counts (finite and longer than the settled length), else 0.
    pub keep: Vec<u8>,
    /// The moved fat point, world (set by [`MoveBatch::finish`]).
    pub q: [Vec<f32>; 3],
    /// Velocity of the shape's surface where the point was left, world, m/s.
    pub surface_vel: [Vec<f32>; 3],
}

impl MoveBatch {
    /// Sizes every array but `q` (which [`MoveBatch::finish`] sets) for `n` entries.
    pub fn resize(&mut self, n: usize) {
        self.converged.resize(n, 0);
        self.len.resize(n, 0.0);
        self.keep.resize(n, 0);
        for c in 0..3 {
            self.d[c].resize(n, 0.0);
            self.normal[c].resize(n, 0.0);
            self.surface_vel[c].resize(n, 0.0);
        }
    }

    /// Fills `converged` from the values and gradients of the batch's last evaluation.
    pub fn mark_converged(&mut self, value: &[f32], grad: &[Vec<f32>; 3]) {
        let [gx, gy, gz] = grad;
        converged_pass(value, gx, gy, gz, &mut self.converged);
    }

    /// Fills `d`, `len`, `normal` and `keep` for the shape-frame targets `p` of the entries
    /// that started at `origin`: `d = world_from_shape.matrix3 · (p − origin)`, kept when
    /// finite and `|d|² > settled_m²`.
    pub fn world_moves(
        &mut self,
        world_from_shape: &Affine3A,
        p: &[Vec<f32>; 3],
        origin: &[Vec<f32>; 3],
        settled_m: f32,
    ) {
        let [px, py, pz] = p;
        let [ox, oy, oz] = origin;
        let [dx, dy, dz] = &mut self.d;
        let [nx, ny, nz] = &mut self.normal;
        world_moves_pass(
            world_from_shape,
            settled_m * settled_m,
            px,
            py,
            pz,
            ox,
            oy,
            oz,
            dx,
            dy,
            dz,
            &mut self.len,
            nx,
            ny,
            nz,
            &mut self.keep,
        );
    }

    /// Sets `q` to the fat points of the entries' free points `point` (read from the world SoA
    /// arrays `fat_points`) moved by `d`, and `surface_vel` to the velocity of the surface
    /// point now under each: it was at `start_world_from_shape(end_shape_from_world(q))` at the
    /// start of the step, `inv_h_per_s` before. `None` (the step's shapes differ): the surface
    /// counts as still.
    pub fn finish(
        &mut self,
        point: &[u32],
        fat_points: &[Vec<f32>; 3],
        motion: Option<(&Affine3A, &Affine3A)>,
        inv_h_per_s: f32,
    ) {
        for (q, from) in self.q.iter_mut().zip(fat_points) {
            q.clear();
            q.extend(point.iter().map(|&f| from[f as usize]));
        }
        let [qx, qy, qz] = &mut self.q;
        let [dx, dy, dz] = &self.d;
        move_points(qx, qy, qz, dx, dy, dz);
        let [sx, sy, sz] = &mut self.surface_vel;
        match motion {
            Some((end_shape_from_world, start_world_from_shape)) => surface_velocity_pass(
                end_shape_from_world,
                start_world_from_shape,
                inv_h_per_s,
                qx,
                qy,
                qz,
                sx,
                sy,
                sz,
            ),
            None => {
                for c in [sx, sy, sz] {
                    c.fill(0.0);
                }
            }
        }
    }
}

crate::sim::simd::multiversion! {
    /// `out[i] = 1` where the entry is on the surface ([`on_surface`], the test the batched
    /// Newton steps make).
    fn converged_pass(value: &[f32], gx: &[f32], gy: &[f32], gz: &[f32], out: &mut [u8]) {
        let n = out.len().min(value.len()).min(gx.len()).min(gy.len()).min(gz.len());
        for i in 0..n {
            let len2 = (gx[i] * gx[i]) + (gy[i] * gy[i]) + (gz[i] * gz[i]);
            out[i] = u8::from(on_surface(value[i], len2));
        }
    }
}

crate::sim::simd::multiversion! {
    fn world_moves_pass(
        world_from_shape: &Affine3A,
        settled2: f32,
        px: &[f32],
        py: &[f32],
        pz: &[f32],
        ox: &[f32],
        oy: &[f32],
        oz: &[f32],
        dx: &mut [f32],
        dy: &mut [f32],
        dz: &mut [f32],
        len: &mut [f32],
        nx: &mut [f32],
        ny: &mut [f32],
        nz: &mut [f32],
        keep: &mut [u8],
    ) {
        let n = keep.len().min(px.len()).min(py.len()).min(pz.len());
        let n = n.min(ox.len()).min(oy.len()).min(oz.len());
        let n = n.min(dx.len()).min(dy.len()).min(dz.len()).min(len.len());
        let n = n.min(nx.len()).min(ny.len()).min(nz.len());
        let m = world_from_shape.matrix3;
        let (cx, cy, cz) = (m.x_axis, m.y_axis, m.z_axis);
        for i in 0..n {
            let (lx, ly, lz) = (px[i] - ox[i], py[i] - oy[i], pz[i] - oz[i]);
            let wx = ((cx.x * lx) + (cy.x * ly)) + (cz.x * lz);
            let wy = ((cx.y * lx) + (cy.y * ly)) + (cz.y * lz);
            let wz = ((cx.z * lx) + (cy.z * ly)) + (cz.z * lz);
            let len2 = ((wx * wx) + (wy * wy)) + (wz * wz);
            let finite = wx.is_finite() & wy.is_finite() & wz.is_finite();
            let l = len2.sqrt();
            (dx[i], dy[i], dz[i]) = (wx, wy, wz);
            len[i] = l;
            (nx[i], ny[i], nz[i]) = (wx / l, wy / l, wz / l);
            // With finite components `len2` is not NaN, so this is `!(len2 <= settled2)`.
            keep[i] = u8::from(finite & (len2 > settled2));
        }
    }
}

crate::sim::simd::multiversion! {
    /// `q += d`.
    fn move_points(
        qx: &mut [f32],
        qy: &mut [f32],
        qz: &mut [f32],
        dx: &[f32],
        dy: &[f32],
        dz: &[f32],
    ) {
        let n = qx.len().min(qy.len()).min(qz.len()).min(dx.len()).min(dy.len()).min(dz.len());
        for i in 0..n {
            qx[i] += dx[i];
            qy[i] += dy[i];
            qz[i] += dz[i];
        }
    }
}

crate::sim::simd::multiversion! {
    fn surface_velocity_pass(
        end_shape_from_world: &Affine3A,
        start_world_from_shape: &Affine3A,
        inv_h: f32,
        qx: &[f32],
        qy: &[f32],
        qz: &[f32],
        sx: &mut [f32],
        sy: &mut [f32],
        sz: &mut [f32],
    ) {
        let n = qx.len().min(qy.len()).min(qz.len()).min(sx.len()).min(sy.len()).min(sz.len());
        let (a, at) = (end_shape_from_world.matrix3, end_shape_from_world.translation);
        let (b, bt) = (start_world_from_shape.matrix3, start_world_from_shape.translation);
        for i in 0..n {
            let (x, y, z) = (qx[i], qy[i], qz[i]);
            let lx = (((a.x_axis.x * x) + (a.y_axis.x * y)) + (a.z_axis.x * z)) + at.x;
            let ly = (((a.x_axis.y * x) + (a.y_axis.y * y)) + (a.z_axis.y * z)) + at.y;
            let lz = (((a.x_axis.z * x) + (a.y_axis.z * y)) + (a.z_axis.z * z)) + at.z;
            let wx = (((b.x_axis.x * lx) + (b.y_axis.x * ly)) + (b.z_axis.x * lz)) + bt.x;
            let wy = (((b.x_axis.y * lx) + (b.y_axis.y * ly)) + (b.z_axis.y * lz)) + bt.y;
            let wz = (((b.x_axis.z * lx) + (b.y_axis.z * ly)) + (b.z_axis.z * lz)) + bt.z;
            sx[i] = (x - wx) * inv_h;
            sy[i] = (y - wy) * inv_h;
            sz[i] = (z - wz) * inv_h;
        }
    }
}

#[cfg(test)]
mod tests {
    use glam::{Quat, Vec3};

    use super::*;
    use crate::character::PROJECTION_TOLERANCE_M;
    use crate::sim::simd::{SimdLevel, with_simd_level};
    use crate::test_noise::Noise;

    /// The per-point `glam` code these passes replace.
    fn reference(
        world_from_shape: &Affine3A,
        end_shape_from_world: &Affine3A,
        start_world_from_shape: &Affine3A,
        inv_h: f32,
        p: Vec3,
        origin: Vec3,
        q: Vec3,
        settled: f32,
    ) -> Option<(Vec3, Vec3, Vec3, Vec3)> {
        let d = world_from_shape.transform_vector3(p - origin);
        if !d.is_finite() || d.length_squared() <= settled * settled {
            return None;
        }
        let normal = d / d.length();
        let q = q + d;
        let was = start_world_from_shape.transform_point3(end_shape_from_world.transform_point3(q));
        Some((d, normal, q, (q - was) * inv_h))
    }

    fn affine(noise: &mut Noise) -> Affine3A {
        let axis = (noise.vec() + Vec3::Z * 2.0).normalize();
        Affine3A::from_rotation_translation(
            Quat::from_axis_angle(axis, 3.0 * noise.next()),
            noise.vec(),
        )
    }

    #[test]
    fn batched_moves_are_the_per_point_glam_results_bit_for_bit() {
        let mut noise = Noise(11);
        let n = 61;
        let (to_world, end_from_world, start_to_world) =
            (affine(&mut noise), affine(&mut noise), affine(&mut noise));
        let inv_h = 1.0 / 0.0071;
        let settled = 1e-5;
        let mut p: [Vec<f32>; 3] = Default::default();
        let mut origin: [Vec<f32>; 3] = Default::default();
        let mut q: [Vec<f32>; 3] = Default::default();
        for i in 0..n {
            // Moves of 0-2 mm, some below the settled length, one not finite.
            let o = noise.vec() * 0.1;
            let scale = if i % 7 == 0 { 1e-6 } else { 2e-3 };
            let mut target = o + noise.vec() * scale;
            if i == 5 {
                target.x = f32::NAN;
            }
            let world = noise.vec();
            for c in 0..3 {
                p[c].push(target[c]);
                origin[c].push(o[c]);
                q[c].push(world[c]);
            }
        }
        for level in SimdLevel::ALL {
            let mut b = MoveBatch::default();
            b.resize(n);
            let points: Vec<u32> = (0..n as u32).collect();
            let run = |b: &mut MoveBatch| {
                b.world_moves(&to_world, &p, &origin, settled);
                b.finish(&points, &q, Some((&end_from_world, &start_to_world)), inv_h);
            };
            with_simd_level(level, || run(&mut b));
            let mut kept = 0;
            for i in 0..n {
                let at = |a: &[Vec<f32>; 3]| Vec3::new(a[0][i], a[1][i], a[2][i]);
                let want = reference(
                    &to_world,
                    &end_from_world,
                    &start_to_world,
                    inv_h,
                    at(&p),
                    at(&origin),
                    at(&q),
                    settled,
                );
                match want {
                    None => assert_eq!(b.keep[i], 0, "{level:?} {i}"),
                    Some((d, normal, moved, vel)) => {
                        kept += 1;
                        assert_eq!(b.keep[i], 1, "{level:?} {i}");
                        assert_eq!(at(&b.d), d, "{level:?} {i}");
                        assert_eq!(at(&b.normal), normal, "{level:?} {i}");
                        assert_eq!(b.len[i], d.length(), "{level:?} {i}");
                        assert_eq!(at(&b.q), moved, "{level:?} {i}");
                        assert_eq!(at(&b.surface_vel), vel, "{level:?} {i}");
                    }
                }
            }
            assert!(kept > n / 2 && kept < n, "{kept} of {n} kept");
        }
    }

    #[test]
    fn convergence_is_the_first_order_distance_within_the_tolerance() {
        let tol = PROJECTION_TOLERANCE_M;
        // Gradient length 2: F within 2·tol is on the surface; a zero gradient never is.
        let value = [0.0, 1.9 * tol, -1.9 * tol, 2.1 * tol, 0.0];
        let g = [2.0, 2.0, 2.0, 2.0, 0.0];
        let zeros = [0.0; 5];
        let mut b = MoveBatch::default();
        b.resize(5);
        b.mark_converged(&value, &[g.to_vec(), zeros.to_vec(), zeros.to_vec()]);
        assert_eq!(b.converged, [1, 1, 1, 0, 0]);
    }

    #[test]
    fn a_still_surface_has_no_velocity() {
        let mut b = MoveBatch::default();
        b.resize(3);
        b.surface_vel[1][2] = 7.0;
        let q = [vec![1.0; 3], vec![2.0; 3], vec![3.0; 3]];
        b.finish(&[0, 2, 1], &q, None, 100.0);
        assert!(b.surface_vel.iter().flatten().all(|&v| v == 0.0));
    }
}
