//! Inside/outside values and gradients of many points against one shape at once, for the
//! constraint pass ([`super::constraints`]): structure-of-arrays batches, one simple loop per
//! deformation and per primitive, fast branch-free math ([`super::fastmath`]), so the loops
//! vectorise. The character model's shapes (`character::shape`) stay the reference: the
//! formulas are theirs (same `F`, same zero set) and the tests below compare against them.

#![allow(clippy::needless_range_loop)] // index loops over parallel SoA arrays read best as they are

use glam::Vec3;

use super::fastmath::{atan2, pow0, sin_cos};
use crate::character::shape::{MIN_CURVATURE_PER_M, MIN_TAPER_SCALE};
use crate::character::{PROJECTION_TOLERANCE_M, Primitive, Resolved, ShapeGeometry};
use crate::sim::simd::LANES;

/// Points in one shape's frame (structure of arrays) with their values and gradients.
#[derive(Debug, Clone, Default)]
pub struct Batch {
    /// Free-point index of each entry.
    pub point: Vec<u32>,
    /// Shape-space coordinates, metres.
    pub p: [Vec<f32>; 3],
    /// `F` at `p` (negative inside): the first [`len`](Self::len) entries are the last
    /// [`evaluate`](Self::evaluate)'s, any beyond are stale.
    pub value: Vec<f32>,
    /// `∇F` at `p`, shape space (not normalised), of the last evaluation with gradients; as
    /// with `value`, only the first [`len`](Self::len) entries belong to the batch.
    pub grad: [Vec<f32>; 3],
    /// Scratch: rest-space coordinates.
    rest: [Vec<f32>; 3],
    /// Scratch: `∂p_rest/∂p_shape`, row-major.
    jac: [Vec<f32>; 9],
    /// Scratch of the superellipsoid kernel.
    tmp: [Vec<f32>; 5],
    /// Scratch of [`assign_inside_of`](Self::assign_inside_of): per source entry, 1 where it
    /// is chosen, and the chosen entries.
    mask: Vec<u8>,
    chosen: Vec<u32>,
}

impl Batch {
    /// Empties the batch.
    pub fn clear(&mut self) {
        self.point.clear();
        for c in &mut self.p {
            c.clear();
        }
    }

    /// Number of entries.
    pub fn len(&self) -> usize {
        self.point.len()
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.point.is_empty()
    }

    /// Appends a point.
    #[inline]
    pub fn push(&mut self, point: u32, p: Vec3) {
        self.point.push(point);
        self.p[0].push(p.x);
        self.p[1].push(p.y);
        self.p[2].push(p.z);
    }

    /// Replaces the entries with those of `src` whose value is below `−band` (inside, and by
    /// more than `band`; `band ≥ 0`), in order. The chosen entries are listed first (a
    /// vectorised comparison and the word-wise compaction of `masks::collect_hits`, no branch per
    /// entry), then the four arrays are gathered for those alone: about one sign-tested entry
    /// in six is chosen, and compacting all four arrays wrote every entry.
    pub fn assign_inside_of(&mut self, src: &Batch, band: f32) {
        let n = src.len().min(src.value.len());
        self.mask.resize(n.next_multiple_of(8), 0);
        below(&src.value[..n], -band, &mut self.mask[..n]);
        self.mask[n..].fill(0);
        super::masks::collect_hits(&self.mask, &mut self.chosen);
        let k = self.chosen.len();
        self.point.resize(k, 0);
        for c in &mut self.p {
            c.resize(k, 0.0);
        }
        let [px, py, pz] = &mut self.p;
        let (px, py, pz, point) = (
            &mut px[..k],
            &mut py[..k],
            &mut pz[..k],
            &mut self.point[..k],
        );
        let [sx, sy, sz] = &src.p;
        let (sx, sy, sz, spoint) = (&sx[..n], &sy[..n], &sz[..n], &src.point[..n]);
        for (j, &i) in self.chosen.iter().enumerate() {
            let i = i as usize;
            point[j] = spoint[i];
            (px[j], py[j], pz[j]) = (sx[i], sy[i], sz[i]);
        }
    }

    /// One Newton step of every entry towards the surface `F = 0` along the gradient of the
    /// last [`evaluate`](Self::evaluate) with gradients, `p ← p − F ∇F/|∇F|²` (entries whose
    /// gradient is degenerate or whose numbers are not finite stay). Returns whether every
    /// entry was already on the surface before its step (`|F| ≤` the projection tolerance
    /// times `|∇F|`).
    pub fn newton_step(&mut self) -> bool {
        let n = self.len();
        let [px, py, pz] = &mut self.p;
        let [gx, gy, gz] = &self.grad;
        let (px, py, pz) = (&mut px[..n], &mut py[..n], &mut pz[..n]);
        newton_steps(px, py, pz, &self.value[..n], gx, gy, gz)
    }

    /// Appends the points `base + i` for each `i` in `hits`, read from the world SoA arrays `q`
    /// and mapped by `shape_from_world`: gathered by index (one resize per call, not four
    /// pushes per point), then transformed in one vectorised pass.
    pub fn extend_mapped(
        &mut self,
        base: usize,
        hits: &[u32],
        q: &[Vec<f32>; 3],
        shape_from_world: &glam::Affine3A,
    ) {
        let start = self.len();
        let end = start + hits.len();
        self.point.resize(end, 0);
        for c in &mut self.p {
            c.resize(end, 0.0);
        }
        let [px, py, pz] = &mut self.p;
        let (px, py, pz) = (
            &mut px[start..end],
            &mut py[start..end],
            &mut pz[start..end],
        );
        let point = &mut self.point[start..end];
        // One length for the three sources, so each gather is one bounds check.
        let [qx, qy, qz] = q;
        let len = qx.len().min(qy.len()).min(qz.len());
        let (qx, qy, qz) = (&qx[..len], &qy[..len], &qz[..len]);
        for (k, &i) in hits.iter().enumerate() {
            let f = base + i as usize;
            point[k] = f as u32;
            (px[k], py[k], pz[k]) = (qx[f], qy[f], qz[f]);
        }
        transform_points(shape_from_world, px, py, pz);
    }

    /// Entry `i`'s shape-space position.
    #[inline]
    pub fn position(&self, i: usize) -> Vec3 {
        Vec3::new(self.p[0][i], self.p[1][i], self.p[2][i])
    }

    /// Entry `i`'s gradient.
    #[cfg(test)]
    pub fn gradient(&self, i: usize) -> Vec3 {
        Vec3::new(self.grad[0][i], self.grad[1][i], self.grad[2][i])
    }

    /// Fills `value` (and `grad` when `want_gradient`) for every entry against `geometry`.
    /// Without the gradient, `value` only has the sign of `F` (negative inside, zero on the
    /// surface): it is the cheaper `F_raw − 1` without the normalisation, for the filter.
    pub fn evaluate(&mut self, geometry: &ShapeGeometry, want_gradient: bool) {
        let len = self.len();
        // The kernels run over whole vectors: the entries padded with the origin (harmless in
        // every kernel) to a multiple of LANES, so no entry takes a loop's scalar remainder.
        let n = len.next_multiple_of(LANES);
        for c in 0..3 {
            self.p[c].truncate(len);
            self.p[c].resize(n, 0.0);
        }
        self.evaluate_padded(geometry, want_gradient, n);
        for c in 0..3 {
            self.p[c].truncate(len);
        }
    }

    /// [`evaluate`](Self::evaluate) over the first `n` positions of `p` (`n` at least the
    /// batch length: the padding is evaluated too), leaving at least `n` values (and
    /// gradients), of which the first `n` are this call's.
    fn evaluate_padded(&mut self, geometry: &ShapeGeometry, want_gradient: bool, n: usize) {
        // The kernels write every one of the first `n` entries, so the arrays only grow (no
        // zero fill of what is written next; the gradient is left alone for signs only).
        // (Spheres and cylinders always compute their gradient with the value.)
        let superellipsoid_signs =
            !want_gradient && matches!(geometry.primitive, Primitive::Superellipsoid { .. });
        let gn = if superellipsoid_signs { 0 } else { n };
        grow_to(&mut self.value, n);
        if gn > 0 {
            for c in &mut self.grad {
                grow_to(c, n);
            }
        }
        let value = &mut self.value[..n];
        let deformed = !geometry.is_undeformed();
        if deformed {
            for c in 0..3 {
                self.rest[c].clear();
                self.rest[c].extend_from_slice(&self.p[c]);
            }
            if want_gradient {
                for (k, j) in self.jac.iter_mut().enumerate() {
                    j.clear();
                    j.resize(n, if k % 4 == 0 { 1.0 } else { 0.0 });
                }
            }
            let [x, y, z] = &mut self.rest;
            for d in geometry.deformations().iter().rev() {
                match (*d, want_gradient) {
                    (Resolved::Taper { rate_per_m }, true) => {
                        taper(rate_per_m, x, y, z, &mut self.jac)
                    }
                    (Resolved::Taper { rate_per_m }, false) => taper_points(rate_per_m, x, y, z),
                    (Resolved::Twist { rate_rad_per_m }, true) => {
                        twist(rate_rad_per_m, x, y, z, &mut self.jac)
                    }
                    (Resolved::Twist { rate_rad_per_m }, false) => {
                        twist_points(rate_rad_per_m, x, y, z)
                    }
                    (Resolved::Bend { curvature_per_m }, grad) => {
                        if curvature_per_m.abs() >= MIN_CURVATURE_PER_M {
                            if grad {
                                bend(curvature_per_m, x, y, z, &mut self.jac)
                            } else {
                                bend_points(curvature_per_m, x, y)
                            }
                        }
                    }
                }
            }
        }
        let [x, y, z] = if deformed { &self.rest } else { &self.p };
        let [gx, gy, gz] = &mut self.grad;
        let (gx, gy, gz) = (&mut gx[..gn], &mut gy[..gn], &mut gz[..gn]);
        match geometry.primitive {
            Primitive::Sphere { radius_m } => sphere(radius_m, x, y, z, value, gx, gy, gz),
            Primitive::Superellipsoid { radii_m, e1, e2 } => {
                if want_gradient {
                    superellipsoid(radii_m, e1, e2, x, y, z, value, gx, gy, gz, &mut self.tmp)
                } else {
                    superellipsoid_sign(radii_m, e1, e2, x, y, z, value)
                }
            }
            Primitive::Cylinder {
                radius_m,
                half_length_m,
            } => cylinder(radius_m, half_length_m, x, y, z, value, gx, gy, gz),
        }
        if deformed && want_gradient {
            gradient_to_shape(&self.jac, gx, gy, gz);
        }
    }
}

/// Makes `v` at least `n` long, zero-filling only what it adds.
fn grow_to(v: &mut Vec<f32>, n: usize) {
    if v.len() < n {
        v.resize(n, 0.0);
    }
}

/// Whether `F` with a gradient of squared length `grad_len2` is on the surface: `|∇F| > 0` and
/// the first-order distance `|F| / |∇F|` within [`PROJECTION_TOLERANCE_M`].
#[inline(always)]
pub(super) fn on_surface(value: f32, grad_len2: f32) -> bool {
    let glen = grad_len2.sqrt();
    (glen > 0.0) & (value.abs() <= PROJECTION_TOLERANCE_M * glen)
}

crate::sim::simd::multiversion! {
    /// `mask[i] = 1` where `value[i] < limit`, else 0.
    fn below(value: &[f32], limit: f32, mask: &mut [u8]) {
        let n = value.len().min(mask.len());
        let (value, mask) = (&value[..n], &mut mask[..n]);
        for i in 0..n {
            mask[i] = u8::from(value[i] < limit);
        }
    }
}

crate::sim::simd::multiversion! {
    /// One Newton step towards `F = 0` along the gradient, `p ← p − F ∇F/|∇F|²`, for every
    /// entry (SoA positions, values and gradients; entries whose gradient is degenerate or
    /// whose numbers are not finite stay). Returns whether every entry was already on the
    /// surface before its step: `|F| ≤ PROJECTION_TOLERANCE_M · |∇F|`, a first-order distance
    /// within the projection tolerance.
    fn newton_steps(
        px: &mut [f32],
        py: &mut [f32],
        pz: &mut [f32],
        value: &[f32],
        gx: &[f32],
        gy: &[f32],
        gz: &[f32],
    ) -> bool {
        let n = px.len().min(py.len()).min(pz.len()).min(value.len());
        let n = n.min(gx.len()).min(gy.len()).min(gz.len());
        let mut all_converged = true;
        for i in 0..n {
            let (x, y, z, v) = (gx[i], gy[i], gz[i], value[i]);
            let len2 = x * x + y * y + z * z;
            all_converged &= on_surface(v, len2);
            let step = (len2 > 1e-12) & v.is_finite() & len2.is_finite();
            let k = v / len2;
            let (nx, ny, nz) = (px[i] - x * k, py[i] - y * k, pz[i] - z * k);
            px[i] = if step { nx } else { px[i] };
            py[i] = if step { ny } else { py[i] };
            pz[i] = if step { nz } else { pz[i] };
        }
        all_converged
    }
}

crate::sim::simd::multiversion! {
    /// `p ← t(p)` for every point (SoA), with the arithmetic of `Affine3A::transform_point3`.
    fn transform_points(t: &glam::Affine3A, x: &mut [f32], y: &mut [f32], z: &mut [f32]) {
        let n = x.len().min(y.len()).min(z.len());
        let (x, y, z) = (&mut x[..n], &mut y[..n], &mut z[..n]);
        let m = t.matrix3;
        let (cx, cy, cz, o) = (m.x_axis, m.y_axis, m.z_axis, t.translation);
        for i in 0..n {
            let (a, b, c) = (x[i], y[i], z[i]);
            x[i] = cx.x * a + cy.x * b + cz.x * c + o.x;
            y[i] = cx.y * a + cy.y * b + cz.y * c + o.y;
            z[i] = cx.z * a + cy.z * b + cz.z * c + o.z;
        }
    }
}

/// One chunk of [`LANES`] entries of the nine Jacobian arrays, copied into locals.
///
/// The Jacobian kernels work chunk by chunk on these copies. Indexed straight through the
/// nine `Vec`s, their loops needed LLVM's run-time overlap checks between twelve arrays (it
/// cannot know that the `Vec`s' buffers are distinct), and the vector loops behind those
/// checks only started at 17 to 33 points (in the AVX-512 copies): every batch of 16 points or
/// fewer ran the scalar remainder. Locals need no checks. (Bit-identical trajectories, the
/// torso 2-4 % and the wombat about 3.5 % faster: docs/simulate.md.)
type JacLanes = [[f32; LANES]; 9];

/// Entries `[start, start + len)` of `jac` (`len ≤ LANES`; a whole chunk when `len` is
/// [`LANES`], which the compiler sees as a constant in the chunk loops), the rest zero.
#[inline(always)]
fn load_jac(jac: &[Vec<f32>; 9], start: usize, len: usize) -> JacLanes {
    let mut lanes = [[0.0; LANES]; 9];
    for (l, j) in lanes.iter_mut().zip(jac) {
        l[..len].copy_from_slice(&j[start..start + len]);
    }
    lanes
}

/// Writes the first `len` lanes back to the entries [`load_jac`] read.
#[inline(always)]
fn store_jac(jac: &mut [Vec<f32>; 9], start: usize, len: usize, lanes: &JacLanes) {
    for (j, l) in jac.iter_mut().zip(lanes) {
        j[start..start + len].copy_from_slice(&l[..len]);
    }
}

/// Entries `[start, start + len)` of `s` (`len ≤ LANES`), the rest zero.
#[inline(always)]
fn load_lanes(s: &[f32], start: usize, len: usize) -> [f32; LANES] {
    let mut lanes = [0.0; LANES];
    lanes[..len].copy_from_slice(&s[start..start + len]);
    lanes
}

/// `jac ← J_d · jac` on lane `l` of a chunk, for the rows of `J_d` (row-major).
#[inline(always)]
fn accumulate_lane(jac: &mut JacLanes, l: usize, rows: [[f32; 3]; 3]) {
    let old = [
        [jac[0][l], jac[1][l], jac[2][l]],
        [jac[3][l], jac[4][l], jac[5][l]],
        [jac[6][l], jac[7][l], jac[8][l]],
    ];
    for r in 0..3 {
        for c in 0..3 {
            jac[3 * r + c][l] =
                rows[r][0] * old[0][c] + rows[r][1] * old[1][c] + rows[r][2] * old[2][c];
        }
    }
}

/// The length every Jacobian array has (the shortest).
#[inline(always)]
fn jac_len(jac: &[Vec<f32>; 9]) -> usize {
    jac.iter().map(Vec::len).min().unwrap_or(0)
}

/// One inverse deformation (deformed → rest) of a single point, with its Jacobian: from the
/// point's coordinates `(a, b, c)`, of which it changes `a` and `c` and only reads `b`, to the
/// new `a` and `c` and the rows of the Jacobian (in x, y, z order). The kernels below apply
/// it to every point with [`deform_with_jacobian`].
trait PointDeformation {
    fn apply(&self, a: f32, b: f32, c: f32) -> (f32, f32, [[f32; 3]; 3]);
}

/// The inverse taper at `rate` (per metre along y): `(a, b, c) = (x, y, z)`.
struct Taper(f32);

impl PointDeformation for Taper {
    #[inline(always)]
    fn apply(&self, qx: f32, y: f32, qz: f32) -> (f32, f32, [[f32; 3]; 3]) {
        let raw = 1.0 + self.0 * y;
        let clamped = raw <= MIN_TAPER_SCALE;
        let r = if clamped { MIN_TAPER_SCALE } else { raw };
        let dr = if clamped { 0.0 } else { self.0 };
        let inv = 1.0 / r;
        let k = dr * inv * inv;
        let rows = [[inv, -qx * k, 0.0], [0.0, 1.0, 0.0], [0.0, -qz * k, inv]];
        (qx * inv, qz * inv, rows)
    }
}

/// The inverse twist at `rate` (radians per metre along y): `(a, b, c) = (x, y, z)`.
struct Twist(f32);

impl PointDeformation for Twist {
    #[inline(always)]
    fn apply(&self, qx: f32, y: f32, qz: f32) -> (f32, f32, [[f32; 3]; 3]) {
        let w = self.0;
        let (s, c) = sin_cos(w * y);
        let nx = qx * c + qz * s;
        let nz = -qx * s + qz * c;
        (nx, nz, [[c, w * nz, s], [0.0, 1.0, 0.0], [-s, -w * nx, c]])
    }
}

/// The inverse bend of curvature `k` (per metre; `inv_k = 1/k`): `(a, b, c) = (x, z, y)`, z
/// unused.
struct Bend {
    k: f32,
    inv_k: f32,
}

impl PointDeformation for Bend {
    #[inline(always)]
    fn apply(&self, qx: f32, _z: f32, qy: f32) -> (f32, f32, [[f32; 3]; 3]) {
        let k = self.k;
        let ky = k * qy;
        let omk = 1.0 - k * qx;
        let theta = atan2(ky, omk);
        let rho = (ky * ky + omk * omk).sqrt();
        let nx = -(k * qy * qy - 2.0 * qx + k * qx * qx) / (1.0 + rho);
        let ny = theta * self.inv_k;
        let ok = rho > 1e-12;
        let inv_rho = if ok { 1.0 / rho } else { 0.0 };
        // sin θ and cos θ of θ = atan2(ky, 1 − kx) without trigonometry.
        let s = if ok { ky * inv_rho } else { 0.0 };
        let c = if ok { omk * inv_rho } else { 1.0 };
        (
            nx,
            ny,
            [
                [c, -s, 0.0],
                [s * inv_rho, c * inv_rho, 0.0],
                [0.0, 0.0, 1.0],
            ],
        )
    }
}

/// `d` applied to every point, in place, with `jac ← J_d · jac` ([`PointDeformation`] names
/// which coordinate array is which), chunk by chunk on local copies ([`JacLanes`]): whole
/// chunks of [`LANES`] points, then the last, partial one through zero-padded lanes (every
/// deformation takes the origin harmlessly; [`Batch::evaluate`] pads its batches to whole
/// chunks anyway).
#[inline(always)]
fn deform_with_jacobian(
    d: &impl PointDeformation,
    a: &mut [f32],
    b: &[f32],
    c: &mut [f32],
    jac: &mut [Vec<f32>; 9],
) {
    let n = a.len().min(b.len()).min(c.len()).min(jac_len(jac));
    let whole = n / LANES * LANES;
    for start in (0..whole).step_by(LANES) {
        let at = start..start + LANES;
        let (a, b, c) = (&mut a[at.clone()], &b[at.clone()], &mut c[at]);
        let mut j = load_jac(jac, start, LANES);
        for l in 0..LANES {
            (a[l], c[l]) = deform_lane(d, a[l], b[l], c[l], &mut j, l);
        }
        store_jac(jac, start, LANES, &j);
    }
    let len = n - whole;
    if len > 0 {
        let (mut ta, tb, mut tc) = (
            load_lanes(a, whole, len),
            load_lanes(b, whole, len),
            load_lanes(c, whole, len),
        );
        let mut j = load_jac(jac, whole, len);
        for l in 0..LANES {
            (ta[l], tc[l]) = deform_lane(d, ta[l], tb[l], tc[l], &mut j, l);
        }
        a[whole..n].copy_from_slice(&ta[..len]);
        c[whole..n].copy_from_slice(&tc[..len]);
        store_jac(jac, whole, len, &j);
    }
}

/// `d` on one lane: the new `a` and `c`, with lane `l` of `jac` updated.
#[inline(always)]
fn deform_lane(
    d: &impl PointDeformation,
    a: f32,
    b: f32,
    c: f32,
    jac: &mut JacLanes,
    l: usize,
) -> (f32, f32) {
    let (na, nc, rows) = d.apply(a, b, c);
    accumulate_lane(jac, l, rows);
    (na, nc)
}

// The inverse deformations (deformed → rest) as `Resolved::invert`, in place, with (`taper`,
// `twist`, `bend`) or without (`*_points`) their Jacobians.

crate::sim::simd::multiversion! {
    fn taper(rate: f32, x: &mut [f32], y: &[f32], z: &mut [f32], jac: &mut [Vec<f32>; 9]) {
        deform_with_jacobian(&Taper(rate), x, y, z, jac);
    }
}

crate::sim::simd::multiversion! {
    fn taper_points(rate: f32, x: &mut [f32], y: &[f32], z: &mut [f32]) {
        let n = x.len().min(y.len()).min(z.len());
        let (x, y, z) = (&mut x[..n], &y[..n], &mut z[..n]);
        for i in 0..n {
            let raw = 1.0 + rate * y[i];
            let inv = 1.0 / if raw <= MIN_TAPER_SCALE { MIN_TAPER_SCALE } else { raw };
            x[i] *= inv;
            z[i] *= inv;
        }
    }
}

crate::sim::simd::multiversion! {
    fn twist(w: f32, x: &mut [f32], y: &[f32], z: &mut [f32], jac: &mut [Vec<f32>; 9]) {
        deform_with_jacobian(&Twist(w), x, y, z, jac);
    }
}

crate::sim::simd::multiversion! {
    fn twist_points(w: f32, x: &mut [f32], y: &[f32], z: &mut [f32]) {
        let n = x.len().min(y.len()).min(z.len());
        let (x, y, z) = (&mut x[..n], &y[..n], &mut z[..n]);
        for i in 0..n {
            let (s, c) = sin_cos(w * y[i]);
            let (qx, qz) = (x[i], z[i]);
            x[i] = qx * c + qz * s;
            z[i] = -qx * s + qz * c;
        }
    }
}

crate::sim::simd::multiversion! {
    fn bend(k: f32, x: &mut [f32], y: &mut [f32], z: &[f32], jac: &mut [Vec<f32>; 9]) {
        // The inverse bend changes x and y and leaves z alone (it only bounds the length).
        deform_with_jacobian(&Bend { k, inv_k: 1.0 / k }, x, z, y, jac);
    }
}

crate::sim::simd::multiversion! {
    fn bend_points(k: f32, x: &mut [f32], y: &mut [f32]) {
        let n = x.len().min(y.len());
        let (x, y) = (&mut x[..n], &mut y[..n]);
        let inv_k = 1.0 / k;
        for i in 0..n {
            let (qx, qy) = (x[i], y[i]);
            let ky = k * qy;
            let omk = 1.0 - k * qx;
            let rho = (ky * ky + omk * omk).sqrt();
            x[i] = -(k * qy * qy - 2.0 * qx + k * qx * qx) / (1.0 + rho);
            y[i] = atan2(ky, omk) * inv_k;
        }
    }
}

crate::sim::simd::multiversion! {
    /// `∇_shape F = Jᵀ ∇_rest F`.
    fn gradient_to_shape(jac: &[Vec<f32>; 9], gx: &mut [f32], gy: &mut [f32], gz: &mut [f32]) {
        // Chunk by chunk on local copies of the Jacobian, as `deform_with_jacobian`.
        let n = gx.len().min(gy.len()).min(gz.len()).min(jac_len(jac));
        let whole = n / LANES * LANES;
        for start in (0..whole).step_by(LANES) {
            let at = start..start + LANES;
            let (xs, ys, zs) = (&mut gx[at.clone()], &mut gy[at.clone()], &mut gz[at]);
            let j = load_jac(jac, start, LANES);
            for l in 0..LANES {
                (xs[l], ys[l], zs[l]) = transpose_times(&j, l, [xs[l], ys[l], zs[l]]);
            }
        }
        let len = n - whole;
        if len > 0 {
            let mut t = [
                load_lanes(gx, whole, len),
                load_lanes(gy, whole, len),
                load_lanes(gz, whole, len),
            ];
            let j = load_jac(jac, whole, len);
            for l in 0..LANES {
                (t[0][l], t[1][l], t[2][l]) = transpose_times(&j, l, [t[0][l], t[1][l], t[2][l]]);
            }
            gx[whole..n].copy_from_slice(&t[0][..len]);
            gy[whole..n].copy_from_slice(&t[1][..len]);
            gz[whole..n].copy_from_slice(&t[2][..len]);
        }
    }
}

/// `Jᵀ g` for lane `l` of a chunk of Jacobians (row-major).
#[inline(always)]
fn transpose_times(j: &JacLanes, l: usize, g: [f32; 3]) -> (f32, f32, f32) {
    (
        dot3([j[0][l], j[3][l], j[6][l]], g),
        dot3([j[1][l], j[4][l], j[7][l]], g),
        dot3([j[2][l], j[5][l], j[8][l]], g),
    )
}

/// `a · b` as `a₀b₀ + a₁b₁ + a₂b₂`, summed left to right.
#[inline(always)]
fn dot3(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

crate::sim::simd::multiversion! {
    fn sphere(
        radius_m: f32,
        x: &[f32],
        y: &[f32],
        z: &[f32],
        value: &mut [f32],
        gx: &mut [f32],
        gy: &mut [f32],
        gz: &mut [f32],
    ) {
        let n = value.len().min(x.len()).min(y.len()).min(z.len());
        let (gx, gy, gz) = (&mut gx[..n], &mut gy[..n], &mut gz[..n]);
        for i in 0..n {
            let len = (x[i] * x[i] + y[i] * y[i] + z[i] * z[i]).sqrt();
            let ok = len > 0.0;
            let inv = if ok { 1.0 / len } else { 0.0 };
            value[i] = len - radius_m;
            gx[i] = x[i] * inv;
            gy[i] = if ok { y[i] * inv } else { 1.0 };
            gz[i] = z[i] * inv;
        }
    }
}

crate::sim::simd::multiversion! {
    /// The shape model's cylinder (`character::shape`): the signed distance to the nearest
    /// face inside and beside the cylinder, to the rim beyond both, and its gradient; the same
    /// operations in the same order as the model, branch-free, so the values are its bits.
    fn cylinder(
        radius_m: f32,
        half_length_m: f32,
        x: &[f32],
        y: &[f32],
        z: &[f32],
        value: &mut [f32],
        gx: &mut [f32],
        gy: &mut [f32],
        gz: &mut [f32],
    ) {
        let n = value.len().min(x.len()).min(y.len()).min(z.len());
        let (x, y, z, value) = (&x[..n], &y[..n], &z[..n], &mut value[..n]);
        let (gx, gy, gz) = (&mut gx[..n], &mut gy[..n], &mut gz[..n]);
        for i in 0..n {
            let (px, py, pz) = (x[i], y[i], z[i]);
            let rho = (px * px + pz * pz).sqrt();
            // The radial direction (X on the axis) and the axial one.
            let on_axis = rho <= 0.0;
            let rx = if on_axis { 1.0 } else { px / rho };
            let rz = if on_axis { 0.0 } else { pz / rho };
            let ay = if py >= 0.0 { 1.0 } else { -1.0 };
            let dx = rho - radius_m;
            let dy = py.abs() - half_length_m;
            let rim = (dx > 0.0) & (dy > 0.0);
            let side = dx > dy;
            let d = (dx * dx + dy * dy).sqrt();
            // Beyond the rim: (radial dx + axial dy) / d, component by component.
            let (cx, cy, cz) = (
                (rx * dx + 0.0 * dy) / d,
                (0.0 * dx + ay * dy) / d,
                (rz * dx + 0.0 * dy) / d,
            );
            value[i] = if rim { d } else if side { dx } else { dy };
            gx[i] = if rim { cx } else if side { rx } else { 0.0 };
            gy[i] = if rim { cy } else if side { 0.0 } else { ay };
            gz[i] = if rim { cz } else if side { rz } else { 0.0 };
        }
    }
}

crate::sim::simd::multiversion! {
    /// The shape model's superellipsoid `F = s·f^(e1/2) − 1` on the point scaled into the unit
    /// box (`character::shape`), and its gradient. One loop per term (each branch-free);
    /// `tmp` is scratch.
    fn superellipsoid(
        radii: Vec3,
        e1: f32,
        e2: f32,
        x: &[f32],
        y: &[f32],
        z: &[f32],
        value: &mut [f32],
        gx: &mut [f32],
        gy: &mut [f32],
        gz: &mut [f32],
        tmp: &mut [Vec<f32>; 5],
    ) {
        let n = value.len().min(x.len()).min(y.len()).min(z.len());
        let (x, y, z, value) = (&x[..n], &y[..n], &z[..n], &mut value[..n]);
        let (gx, gy, gz) = (&mut gx[..n], &mut gy[..n], &mut gz[..n]);
        for t in tmp.iter_mut() {
            t.resize(n, 0.0);
        }
        let [scale, px, py, pz, a_pow] = tmp;
        let (scale, px, py, pz, a_pow) =
            (&mut scale[..n], &mut px[..n], &mut py[..n], &mut pz[..n], &mut a_pow[..n]);
        let inv_r = Vec3::ONE / radii;
        // The point scaled into the unit box: q = |p|/(radii·s), s = max component (gx,gy,gz
        // hold q until the end).
        for i in 0..n {
            let (ux, uy, uz) = (x[i].abs() * inv_r.x, y[i].abs() * inv_r.y, z[i].abs() * inv_r.z);
            let s = ux.max(uy).max(uz);
            let inv_s = if s > 0.0 && s < f32::INFINITY { 1.0 / s } else { 0.0 };
            scale[i] = s;
            gx[i] = ux * inv_s;
            gy[i] = uy * inv_s;
            gz[i] = uz * inv_s;
        }
        if e1 == 1.0 && e2 == 1.0 {
            for i in 0..n {
                let (qx, qy, qz) = (gx[i], gy[i], gz[i]);
                let root = (qx * qx + qy * qy + qz * qz).sqrt();
                let valid = root > 0.0;
                let inv = if valid { 1.0 / root } else { 0.0 };
                value[i] = if valid { scale[i] * root - 1.0 } else { -1.0 };
                gx[i] = (qx * inv * inv_r.x).copysign(x[i]);
                gy[i] = if valid { (qy * inv * inv_r.y).copysign(y[i]) } else { 1.0 };
                gz[i] = (qz * inv * inv_r.z).copysign(z[i]);
            }
            return;
        }
        let (exp_xz, exp_y, exp_a, exp_f) = (2.0 / e2, 2.0 / e1, e2 / e1, 0.5 * e1);
        if e2 == 1.0 {
            for i in 0..n {
                px[i] = gx[i] * gx[i];
                pz[i] = gz[i] * gz[i];
            }
        } else {
            for i in 0..n {
                px[i] = pow0(gx[i], exp_xz);
                pz[i] = pow0(gz[i], exp_xz);
            }
        }
        for i in 0..n {
            py[i] = pow0(gy[i], exp_y);
            a_pow[i] = pow0(px[i] + pz[i], exp_a);
        }
        for i in 0..n {
            let (qx, qy, qz) = (gx[i], gy[i], gz[i]);
            let big_a = px[i] + pz[i];
            let f = a_pow[i] + py[i];
            let f_pow = pow0(f, exp_f);
            let valid = f > 0.0;
            let f_term = if valid { f_pow / f } else { 0.0 };
            let a_term = if big_a > 0.0 { a_pow[i] / big_a } else { 0.0 };
            let dx = f_term * a_term * if qx > 0.0 { px[i] / qx } else { 0.0 };
            let dy = f_term * if qy > 0.0 { py[i] / qy } else { 0.0 };
            let dz = f_term * a_term * if qz > 0.0 { pz[i] / qz } else { 0.0 };
            value[i] = if valid { scale[i] * f_pow - 1.0 } else { -1.0 };
            gx[i] = (dx * inv_r.x).copysign(x[i]);
            gy[i] = if valid { (dy * inv_r.y).copysign(y[i]) } else { 1.0 };
            gz[i] = (dz * inv_r.z).copysign(z[i]);
        }
    }
}

crate::sim::simd::multiversion! {
    /// `F_raw − 1` with `F_raw = (|x/a|^(2/e2) + |z/c|^(2/e2))^(e2/e1) + |y/b|^(2/e1)`: the
    /// same sign as `F` (the model's `F + 1` is a positive power of `F_raw` for the points of a
    /// batch, which lie in the shape's extent box so nothing overflows), fewer powers. One
    /// loop per term so that every loop is branch-free.
    fn superellipsoid_sign(
        radii: Vec3,
        e1: f32,
        e2: f32,
        x: &[f32],
        y: &[f32],
        z: &[f32],
        value: &mut [f32],
    ) {
        let n = value.len().min(x.len()).min(y.len()).min(z.len());
        let (x, y, z, value) = (&x[..n], &y[..n], &z[..n], &mut value[..n]);
        let inv_r = Vec3::ONE / radii;
        let (exp_xz, exp_y, exp_a) = (2.0 / e2, 2.0 / e1, e2 / e1);
        // value ← A = |x/a|^(2/e2) + |z/c|^(2/e2)
        if e2 == 1.0 {
            for i in 0..n {
                let (ux, uz) = (x[i] * inv_r.x, z[i] * inv_r.z);
                value[i] = ux * ux + uz * uz;
            }
        } else {
            for i in 0..n {
                let (ux, uz) = (x[i].abs() * inv_r.x, z[i].abs() * inv_r.z);
                value[i] = pow0(ux, exp_xz) + pow0(uz, exp_xz);
            }
        }
        // value ← A^(e2/e1)
        if e2 != e1 {
            for v in value.iter_mut() {
                *v = pow0(*v, exp_a);
            }
        }
        // value ← value + |y/b|^(2/e1) − 1
        if e1 == 1.0 {
            for i in 0..n {
                let uy = y[i] * inv_r.y;
                value[i] += uy * uy - 1.0;
            }
        } else {
            for i in 0..n {
                value[i] += pow0(y[i].abs() * inv_r.y, exp_y) - 1.0;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_noise::Noise;

    fn geometries() -> Vec<ShapeGeometry> {
        let prims = [
            Primitive::Sphere { radius_m: 0.07 },
            Primitive::Cylinder {
                radius_m: 0.03,
                half_length_m: 0.12,
            },
            Primitive::Superellipsoid {
                radii_m: Vec3::new(0.08, 0.15, 0.1),
                e1: 0.6,
                e2: 1.4,
            },
            Primitive::Superellipsoid {
                radii_m: Vec3::new(0.1, 0.2, 0.12),
                e1: 1.0,
                e2: 1.0,
            },
            Primitive::Superellipsoid {
                radii_m: Vec3::new(0.05, 0.3, 0.05),
                e1: 0.3,
                e2: 1.0,
            },
            Primitive::Superellipsoid {
                radii_m: Vec3::new(0.12, 0.1, 0.09),
                e1: 1.8,
                e2: 0.4,
            },
        ];
        let chains = [
            vec![],
            vec![Resolved::Taper { rate_per_m: 1.5 }],
            vec![Resolved::Taper { rate_per_m: -4.0 }],
            vec![Resolved::Twist {
                rate_rad_per_m: 3.0,
            }],
            vec![Resolved::Bend {
                curvature_per_m: -2.0,
            }],
            vec![
                Resolved::Twist {
                    rate_rad_per_m: 3.0,
                },
                Resolved::Bend {
                    curvature_per_m: 2.0,
                },
                Resolved::Taper { rate_per_m: 0.8 },
            ],
        ];
        let mut out = Vec::new();
        for p in prims {
            for c in &chains {
                out.push(ShapeGeometry::new(p, c));
            }
        }
        out
    }

    #[test]
    fn the_cylinder_kernel_gives_the_models_bits() {
        let cylinder = Primitive::Cylinder {
            radius_m: 0.04,
            half_length_m: 0.15,
        };
        let g = ShapeGeometry::new(cylinder, &[]);
        let mut noise = Noise(5);
        let mut batch = Batch::default();
        // Random points, and the special ones: on the axis, on the mid-plane, on the side, the
        // caps and the rim, below and above.
        for k in 0..500u32 {
            batch.push(k, noise.vec() * 0.25);
        }
        for (k, p) in [
            Vec3::ZERO,
            Vec3::new(0.0, 0.2, 0.0),
            Vec3::new(0.0, -0.1, 0.0),
            Vec3::new(0.04, 0.0, 0.0),
            Vec3::new(0.0, 0.15, 0.02),
            Vec3::new(0.04, -0.15, 0.0),
            Vec3::new(-0.05, 0.16, 0.01),
            Vec3::new(0.03, 0.0, -0.03),
        ]
        .into_iter()
        .enumerate()
        {
            batch.push(500 + k as u32, p);
        }
        batch.evaluate(&g, true);
        for i in 0..batch.len() {
            let (v, grad) = cylinder.value_and_gradient(batch.position(i));
            let p = batch.position(i);
            assert_eq!(batch.value[i].to_bits(), v.to_bits(), "value at {p}");
            assert_eq!(
                batch.gradient(i).to_array().map(f32::to_bits),
                grad.to_array().map(f32::to_bits),
                "gradient at {p}"
            );
        }
    }

    #[test]
    fn batches_match_the_character_models_shapes() {
        let mut noise = Noise(17);
        let mut batch = Batch::default();
        for g in geometries() {
            batch.clear();
            for k in 0..600u32 {
                batch.push(k, noise.vec() * 0.3);
            }
            batch.evaluate(&g, true);
            let values = batch.value.clone();
            batch.evaluate(&g, false);
            for i in 0..batch.len() {
                let (v_ref, _) = g.value_and_gradient(batch.position(i));
                if v_ref.abs() > 1e-4 {
                    assert_eq!(
                        batch.value[i] < 0.0,
                        v_ref < 0.0,
                        "{g:?}: sign-only value disagrees"
                    );
                }
            }
            batch.value = values;
            batch.evaluate(&g, true);
            for i in 0..batch.len() {
                let p = batch.position(i);
                let (v_ref, g_ref) = g.value_and_gradient(p);
                let v = batch.value[i];
                assert!(
                    (v - v_ref).abs() <= 2e-5 * v_ref.abs().max(1.0),
                    "{g:?} at {p}: {v} vs {v_ref}"
                );
                if v_ref.abs() > 1e-4 {
                    assert_eq!(
                        v < 0.0,
                        v_ref < 0.0,
                        "{g:?} at {p}: inside/outside disagree"
                    );
                }
                let grad = batch.gradient(i);
                assert!(
                    (grad - g_ref).length() <= 2e-3 * g_ref.length().max(1.0),
                    "{g:?} at {p}: {grad} vs {g_ref}"
                );
            }
        }
    }

    /// The deformation kernels work in whole chunks of [`LANES`] entries and take the rest as
    /// one zero-padded partial chunk; both paths, at every SIMD level, must give each entry the
    /// same bits (the entries' positions and Jacobians after a chain, and the shape-frame
    /// gradient). That the arithmetic itself is right is
    /// `batches_match_the_character_models_shapes`.
    #[test]
    fn chunked_and_remainder_paths_of_the_deformation_kernels_agree() {
        use crate::sim::simd::{SimdLevel, with_simd_level};
        let mut noise = Noise(29);
        let n = 3 * LANES + 5;
        let points: Vec<Vec3> = (0..n).map(|_| noise.vec() * 0.3).collect();
        let grads: Vec<Vec3> = (0..n).map(|_| noise.vec()).collect();
        // Taper, twist and bend (in that order) with their Jacobians, then J^T g.
        let run = |pts: &[Vec3], gs: &[Vec3]| {
            let m = pts.len();
            let mut x: Vec<f32> = pts.iter().map(|p| p.x).collect();
            let mut y: Vec<f32> = pts.iter().map(|p| p.y).collect();
            let mut z: Vec<f32> = pts.iter().map(|p| p.z).collect();
            let mut jac: [Vec<f32>; 9] =
                std::array::from_fn(|k| vec![if k % 4 == 0 { 1.0 } else { 0.0 }; m]);
            taper(-2.5, &mut x, &y, &mut z, &mut jac);
            twist(4.0, &mut x, &y, &mut z, &mut jac);
            bend(1.7, &mut x, &mut y, &z, &mut jac);
            let mut g = [
                gs.iter().map(|g| g.x).collect::<Vec<f32>>(),
                gs.iter().map(|g| g.y).collect(),
                gs.iter().map(|g| g.z).collect(),
            ];
            let [gx, gy, gz] = &mut g;
            gradient_to_shape(&jac, gx, gy, gz);
            let mut bits = Vec::new();
            for i in 0..m {
                let entry: Vec<u32> = [x[i], y[i], z[i], g[0][i], g[1][i], g[2][i]]
                    .into_iter()
                    .chain(jac.iter().map(|j| j[i]))
                    .map(f32::to_bits)
                    .collect();
                bits.push(entry);
            }
            bits
        };
        let reference = with_simd_level(SimdLevel::Baseline, || {
            (0..n)
                .map(|i| run(&points[i..=i], &grads[i..=i]).remove(0))
                .collect::<Vec<_>>()
        });
        assert!(
            reference
                .iter()
                .flatten()
                .all(|&b| f32::from_bits(b).is_finite()),
            "the reference itself is not finite"
        );
        for level in SimdLevel::ALL {
            let chunked = with_simd_level(level, || run(&points, &grads));
            for i in 0..n {
                assert_eq!(chunked[i], reference[i], "{level:?}: entry {i} of {n}");
            }
        }
    }

    #[test]
    fn assign_inside_keeps_the_negative_entries_in_order() {
        let mut src = Batch::default();
        let values = [-1.0, 2.0, -0.5, 0.0, f32::NAN, -3.0, 1e-30];
        for (k, _) in values.iter().enumerate() {
            src.push(
                10 + k as u32,
                Vec3::new(k as f32, 2.0 * k as f32, -(k as f32)),
            );
        }
        src.value = values.to_vec();
        // A destination with stale, longer contents.
        let mut dst = Batch::default();
        for k in 0..9 {
            dst.push(99, Vec3::splat(k as f32));
        }
        dst.assign_inside_of(&src, 0.0);
        assert_eq!(dst.point, [10, 12, 15]);
        for (i, k) in [0usize, 2, 5].into_iter().enumerate() {
            assert_eq!(dst.position(i), src.position(k));
        }
        // A band leaves out the entries less than it below zero.
        dst.assign_inside_of(&src, 0.6);
        assert_eq!(dst.point, [10, 15]);
        dst.assign_inside_of(&Batch::default(), 0.0);
        assert!(dst.is_empty() && dst.p.iter().all(|c| c.is_empty()));
        // Longer batches (whole words of the compaction, and a tail) against a plain filter.
        let mut noise = Noise(3);
        for n in [8, 37, 200] {
            let mut src = Batch::default();
            for k in 0..n {
                src.push(k as u32, noise.vec());
            }
            src.value = (0..n).map(|_| noise.vec().x).collect();
            dst.assign_inside_of(&src, 0.1);
            let want: Vec<u32> = (0..n as u32)
                .filter(|&k| src.value[k as usize] < -0.1)
                .collect();
            assert_eq!(dst.point, want, "{n} entries");
            for (i, &k) in want.iter().enumerate() {
                assert_eq!(dst.position(i), src.position(k as usize));
            }
        }
    }

    #[test]
    fn the_extent_box_contains_every_shape() {
        let mut noise = Noise(23);
        for g in geometries() {
            let e = g.extent_m();
            // Surface points from rest-space radial projections, deformed.
            let mut largest = Vec3::ZERO;
            for _ in 0..4000 {
                let dir = noise.vec();
                if dir.length() < 1e-3 {
                    continue;
                }
                let p = g.deform(g.primitive.radial_projection(dir));
                assert!(
                    p.x.abs() <= e.x * 1.0001
                        && p.y.abs() <= e.y * 1.0001
                        && p.z.abs() <= e.z * 1.0001,
                    "{g:?}: {p} outside {e}"
                );
                largest = largest.max(p.abs());
            }
            // And it is not absurdly loose.
            assert!(
                largest.max_element() >= 0.33 * e.max_element(),
                "{g:?}: {largest} vs {e}"
            );
        }
    }
}
