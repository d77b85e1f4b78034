//! Forces on the skin (LEMAN 4.1.1-4.1.3): the elastic surface by finite differences (eq. 2,
//! `../shared/ELASTIC_SURFACE.md`), connective tissue (eq. 3), gravity (eq. 4) and global damping
//! (eq. 5). Structure-of-arrays `f32`, no allocation per evaluation.
//!
//! # Layout
//! The skin is an M×N grid (M around, periodic; N rows along). Rows 0 and N−1 are fixed to their
//! joints and are not degrees of freedom: the state holds the `P = M·(N−2)` free points as three
//! blocks `[x₀…x_{P−1}, y…, z…]`, free point `f = (j−1)·M + i` for rows `1 ≤ j ≤ N−2`. Each
//! evaluation assembles the full grid (fixed rows interpolated in time, see [`StepKinematics`])
//! into scratch arrays and applies the stencils there.
//!
//! # Elastic force (stretch and shear)
//! With `a₁ = D⁺₁r`, `a₂ = D⁺₂r` (forward differences, periodic around), `G_ij = a_i·a_j` and
//! `α_ij = η_ij (G_ij − G⁰_ij)`, the fluxes `F₁ = α₁₁a₁ + α₁₂a₂`, `F₂ = α₁₂a₁ + α₂₂a₂` are formed at
//! every node of rows 0..N−2 and the force density is `D⁻₁F₁ + D⁻₂F₂` (= −e of the note). The
//! force on a point is the density times its material area `h₁h₂`. This is exactly (up to the
//! constant factor the note absorbs into η) minus the gradient of the discrete energy
//! `Σ h₁h₂ Σ_ij η_ij (G_ij − G⁰_ij)²`, so it conserves energy under a symplectic integrator.
//!
//! # Bending (only where ξ > 0)
//! `B_ij = n̂·D_ij r` with centred second differences `D₁₁`, `D₂₂` and the forward mixed
//! difference `D₁₂`; `β_ij = ξ_ij (B_ij − B⁰_ij)` with the rest curvature `B⁰` taken from the
//! skin's initial shape. Deviation from the note: the force is `−Σ D_ijᵀ(β_ij n̂)` (the gradient
//! of `Σ ξ (B − B⁰)²` with n̂ held fixed) rather than `−D_ij(β_ij D_ij r)`: Terzopoulos' form
//! multiplies by the curvature vector, whose sign flips on a convex tube with outward normals
//! and would then push the wrong way. Fixed-row nodes carry β = 0.

#![allow(clippy::needless_range_loop)] // index loops over parallel SoA arrays read best as they are

use glam::Vec3;

/// Per-step kinematic input of the forces: the fixed rows and tissue anchors at the start and
/// end of the step being attempted, linearly interpolated in between (the anchor velocity is the
/// constant `(end − start)/h`).
#[derive(Debug, Clone, Default)]
pub struct StepKinematics {
    /// Start time of the step, seconds.
    pub t0_s: f64,
    /// Step length, seconds (> 0 while a step is being attempted).
    pub h_s: f64,
    /// Row 0 then row N−1 at the start, world, SoA `[x…, y…, z…]` of `2M` points.
    pub rings_start: [Vec<f32>; 3],
    /// The same at the end of the step.
    pub rings_end: [Vec<f32>; 3],
    /// Tissue anchors at the start, world, SoA.
    pub anchors_start: [Vec<f32>; 3],
    /// Tissue anchors at the end.
    pub anchors_end: [Vec<f32>; 3],
}

/// Connective tissue springs in structure-of-arrays form (only springs on free points).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Springs {
    /// Free-point index of each spring.
    pub point: Vec<u32>,
    /// Index into the character's tissue list (for parameter changes).
    pub source: Vec<u32>,
    /// k_s, N/m.
    pub ks: Vec<f32>,
    /// k_d, N·s/m.
    pub kd: Vec<f32>,
    /// Rest length l⁰, m.
    pub rest_m: Vec<f32>,
    /// The shape carrying each anchor.
    pub shape: Vec<u32>,
    /// Each anchor in its shape's rest space, m.
    pub anchor_rest_m: Vec<Vec3>,
}

impl Springs {
    /// Number of springs.
    pub fn len(&self) -> usize {
        self.point.len()
    }

    /// True when there are none.
    pub fn is_empty(&self) -> bool {
        self.point.is_empty()
    }
}

/// Materials on the full grid (M·N values each, index `j·M + i`) and per free point.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Materials {
    /// η₁₁, η₁₂, η₂₂ (full grid).
    pub eta: [Vec<f32>; 3],
    /// G⁰₁₁, G⁰₁₂, G⁰₂₂ (full grid).
    pub rest_metric: [Vec<f32>; 3],
    /// ξ₁₁, ξ₁₂, ξ₂₂ (full grid).
    pub xi: [Vec<f32>; 3],
    /// B⁰₁₁, B⁰₁₂, B⁰₂₂ rest curvature (full grid).
    pub rest_curvature: [Vec<f32>; 3],
    /// Whether any ξ is non-zero (the bending pass is skipped otherwise).
    pub has_bending: bool,
    /// Point mass, kg (free points).
    pub mass_kg: Vec<f32>,
    /// 1/mass (free points).
    pub inv_mass: Vec<f32>,
    /// γ/mass, 1/s (free points).
    pub damping_per_mass: Vec<f32>,
    /// γ, N·s/m (free points).
    pub damping: Vec<f32>,
    /// Fat thickness τ, m (free points).
    pub fat_m: Vec<f32>,
    /// Gravity, m/s².
    pub gravity: Vec3,
}

/// Scratch and cached values of the force evaluation.
#[derive(Debug, Clone, Default)]
pub struct ForceScratch {
    /// Full-grid positions of the last position evaluation.
    pub grid: [Vec<f32>; 3],
    flux1: [Vec<f32>; 3],
    flux2: [Vec<f32>; 3],
    normals: [Vec<f32>; 3],
    beta: [Vec<f32>; 3],
    /// Per spring: unit direction from anchor to point (zero when slack).
    spring_dir: [Vec<f32>; 3],
    /// Per spring: the position part of the pull magnitude, k_s(|l| − l⁰) (0 when slack).
    spring_pos: Vec<f32>,
    /// Per spring: anchor velocity over the current step.
    anchor_vel: [Vec<f32>; 3],
}

/// Everything the forces need for one evaluation.
pub struct ForceInput<'a> {
    /// M.
    pub around: usize,
    /// N.
    pub along: usize,
    /// Materials.
    pub materials: &'a Materials,
    /// Springs.
    pub springs: &'a Springs,
    /// Start/end kinematics of the step.
    pub kin: &'a StepKinematics,
}

impl ForceInput<'_> {
    fn lambda(&self, t_s: f64) -> f32 {
        if self.kin.h_s > 0.0 {
            (((t_s - self.kin.t0_s) / self.kin.h_s) as f32).clamp(0.0, 1.0)
        } else {
            0.0
        }
    }
}

fn resize3(v: &mut [Vec<f32>; 3], n: usize) {
    for a in v {
        if a.len() != n {
            a.resize(n, 0.0);
        }
    }
}

/// Fills the full grid from the free state and the fixed rows interpolated at `lambda`.
pub fn assemble_grid(
    around: usize,
    along: usize,
    x: &[f32],
    rings_start: &[Vec<f32>; 3],
    rings_end: &[Vec<f32>; 3],
    lambda: f32,
    grid: &mut [Vec<f32>; 3],
) {
    let m = around;
    let total = m * along;
    let free = m * (along - 2);
    resize3(grid, total);
    for c in 0..3 {
        let g = &mut grid[c];
        let (rs, re) = (&rings_start[c], &rings_end[c]);
        for i in 0..m {
            g[i] = rs[i] + lambda * (re[i] - rs[i]);
            g[total - m + i] = rs[m + i] + lambda * (re[m + i] - rs[m + i]);
        }
        g[m..m + free].copy_from_slice(&x[c * free..(c + 1) * free]);
    }
}

/// Unit outward normals on the full grid (central differences around, one-sided along at the
/// fixed rows; `∂r/∂u₂ × ∂r/∂u₁`), SoA. Degenerate points get +Y.
pub fn grid_normals(around: usize, along: usize, grid: &[Vec<f32>; 3], out: &mut [Vec<f32>; 3]) {
    let m = around;
    resize3(out, m * along);
    let [gx, gy, gz] = grid;
    for j in 0..along {
        let jp = if j + 1 < along { j + 1 } else { j };
        let jm = j.saturating_sub(1);
        for i in 0..m {
            let ip = if i + 1 == m { 0 } else { i + 1 };
            let im = if i == 0 { m - 1 } else { i - 1 };
            let (a, b) = (j * m + ip, j * m + im);
            let (c, d) = (jp * m + i, jm * m + i);
            let d1 = [gx[a] - gx[b], gy[a] - gy[b], gz[a] - gz[b]];
            let d2 = [gx[c] - gx[d], gy[c] - gy[d], gz[c] - gz[d]];
            let nx = d2[1] * d1[2] - d2[2] * d1[1];
            let ny = d2[2] * d1[0] - d2[0] * d1[2];
            let nz = d2[0] * d1[1] - d2[1] * d1[0];
            let len2 = nx * nx + ny * ny + nz * nz;
            let k = j * m + i;
            if len2 > 1e-24 && len2.is_finite() {
                let inv = 1.0 / len2.sqrt();
                out[0][k] = nx * inv;
                out[1][k] = ny * inv;
                out[2][k] = nz * inv;
            } else {
                out[0][k] = 0.0;
                out[1][k] = 1.0;
                out[2][k] = 0.0;
            }
        }
    }
}

/// `a = M⁻¹ f_position(t, x)`: elastic, tissue (position part), gravity.
pub fn position_accel(
    input: &ForceInput<'_>,
    scratch: &mut ForceScratch,
    t_s: f64,
    x: &[f32],
    a: &mut [f32],
) {
    let (m, n) = (input.around, input.along);
    let free = m * (n - 2);
    let lambda = input.lambda(t_s);
    assemble_grid(
        m,
        n,
        x,
        &input.kin.rings_start,
        &input.kin.rings_end,
        lambda,
        &mut scratch.grid,
    );
    elastic_stretch(input, scratch, a);
    if input.materials.has_bending {
        elastic_bending(input, scratch, a);
    }
    // a = force / m + g
    let mat = input.materials;
    let g = [mat.gravity.x, mat.gravity.y, mat.gravity.z];
    for (c, gc) in g.iter().enumerate() {
        let ac = &mut a[c * free..(c + 1) * free];
        for (ai, im) in ac.iter_mut().zip(&mat.inv_mass) {
            *ai = *ai * im + gc;
        }
    }
    tissue_position(input, scratch, lambda, x, a);
}

fn elastic_stretch(input: &ForceInput<'_>, scratch: &mut ForceScratch, a: &mut [f32]) {
    let (m, n) = (input.around, input.along);
    let free = m * (n - 2);
    let flux_len = m * (n - 1);
    resize3(&mut scratch.flux1, flux_len);
    resize3(&mut scratch.flux2, flux_len);
    let inv_h1 = m as f32;
    let inv_h2 = (n - 1) as f32;
    let (h1, h2) = (1.0 / inv_h1, 1.0 / inv_h2);
    let mat = input.materials;
    let [gx, gy, gz] = &scratch.grid;
    let [e11, e12, e22] = &mat.eta;
    let [g11, g12, g22] = &mat.rest_metric;
    let [f1x, f1y, f1z] = &mut scratch.flux1;
    let [f2x, f2y, f2z] = &mut scratch.flux2;
    for j in 0..n - 1 {
        let row = j * m;
        for i in 0..m {
            let k = row + i;
            let k1 = if i + 1 == m { row } else { k + 1 };
            let k2 = k + m;
            let a1 = [
                (gx[k1] - gx[k]) * inv_h1,
                (gy[k1] - gy[k]) * inv_h1,
                (gz[k1] - gz[k]) * inv_h1,
            ];
            let a2 = [
                (gx[k2] - gx[k]) * inv_h2,
                (gy[k2] - gy[k]) * inv_h2,
                (gz[k2] - gz[k]) * inv_h2,
            ];
            let gg11 = a1[0] * a1[0] + a1[1] * a1[1] + a1[2] * a1[2];
            let gg12 = a1[0] * a2[0] + a1[1] * a2[1] + a1[2] * a2[2];
            let gg22 = a2[0] * a2[0] + a2[1] * a2[1] + a2[2] * a2[2];
            let al11 = e11[k] * (gg11 - g11[k]);
            let al12 = e12[k] * (gg12 - g12[k]);
            let al22 = e22[k] * (gg22 - g22[k]);
            f1x[k] = al11 * a1[0] + al12 * a2[0];
            f1y[k] = al11 * a1[1] + al12 * a2[1];
            f1z[k] = al11 * a1[2] + al12 * a2[2];
            f2x[k] = al12 * a1[0] + al22 * a2[0];
            f2y[k] = al12 * a1[1] + al22 * a2[1];
            f2z[k] = al12 * a1[2] + al22 * a2[2];
        }
    }
    // force = h₁h₂ (D⁻₁F₁ + D⁻₂F₂) = h₂ (F₁[k] − F₁[k−e₁]) + h₁ (F₂[k] − F₂[k−M])
    let flux1 = [&*f1x, &*f1y, &*f1z];
    let flux2 = [&*f2x, &*f2y, &*f2z];
    for c in 0..3 {
        let (f1, f2) = (flux1[c], flux2[c]);
        let ac = &mut a[c * free..(c + 1) * free];
        for j in 1..n - 1 {
            let row = j * m;
            let out = &mut ac[(j - 1) * m..j * m];
            let f1r = &f1[row..row + m];
            let f2r = &f2[row..row + m];
            let f2p = &f2[row - m..row];
            out[0] = h2 * (f1r[0] - f1r[m - 1]) + h1 * (f2r[0] - f2p[0]);
            for i in 1..m {
                out[i] = h2 * (f1r[i] - f1r[i - 1]) + h1 * (f2r[i] - f2p[i]);
            }
        }
    }
}

fn elastic_bending(input: &ForceInput<'_>, scratch: &mut ForceScratch, a: &mut [f32]) {
    let (m, n) = (input.around, input.along);
    let free = m * (n - 2);
    let total = m * n;
    let mat = input.materials;
    grid_normals(m, n, &scratch.grid, &mut scratch.normals);
    resize3(&mut scratch.beta, total);
    let (inv_h1, inv_h2) = (m as f32, (n - 1) as f32);
    let (h1, h2) = (1.0 / inv_h1, 1.0 / inv_h2);
    let g = &scratch.grid;
    let nr = &scratch.normals;
    let at = |k: usize| Vec3::new(g[0][k], g[1][k], g[2][k]);
    let idx = |i: usize, j: usize| j * m + (i % m);
    // β at each node (0 on the fixed rows).
    for j in 0..n {
        for i in 0..m {
            let k = j * m + i;
            if j == 0 || j + 1 == n {
                scratch.beta[0][k] = 0.0;
                scratch.beta[1][k] = 0.0;
                scratch.beta[2][k] = 0.0;
                continue;
            }
            let nk = Vec3::new(nr[0][k], nr[1][k], nr[2][k]);
            let p = at(k);
            let d11 = (at(idx(i + 1, j)) - 2.0 * p + at(idx(i + m - 1, j))) * (inv_h1 * inv_h1);
            let d22 = (at(idx(i, j + 1)) - 2.0 * p + at(idx(i, j - 1))) * (inv_h2 * inv_h2);
            let d12 = (at(idx(i + 1, j + 1)) - at(idx(i + 1, j)) - at(idx(i, j + 1)) + p)
                * (inv_h1 * inv_h2);
            scratch.beta[0][k] = mat.xi[0][k] * (nk.dot(d11) - mat.rest_curvature[0][k]);
            scratch.beta[1][k] = mat.xi[1][k] * (nk.dot(d12) - mat.rest_curvature[1][k]);
            scratch.beta[2][k] = mat.xi[2][k] * (nk.dot(d22) - mat.rest_curvature[2][k]);
        }
    }
    // force_q = −h₁h₂ Σ_p β_p n̂_p ∂(D_ij r)_p/∂r_q
    let b = &scratch.beta;
    let w = |k: usize, c: usize| Vec3::new(nr[0][k], nr[1][k], nr[2][k]) * b[c][k];
    for j in 1..n - 1 {
        for i in 0..m {
            let k = j * m + i;
            let (ip, im) = (idx(i + 1, j), idx(i + m - 1, j));
            let (jp, jm) = (idx(i, j + 1), idx(i, j - 1));
            // D₁₁ and D₂₂ are symmetric: (w[+] − 2w + w[−])/h².
            let f11 = (w(ip, 0) - 2.0 * w(k, 0) + w(im, 0)) * (inv_h1 * inv_h1);
            let f22 = (w(jp, 2) - 2.0 * w(k, 2) + w(jm, 2)) * (inv_h2 * inv_h2);
            // (D⁺₁₂)ᵀ w at q: w[q] − w[q−e₁] − w[q−e₂] + w[q−e₁−e₂], over h₁h₂.
            let f12 =
                (w(k, 1) - w(im, 1) - w(jm, 1) + w(idx(i + m - 1, j - 1), 1)) * (inv_h1 * inv_h2);
            let f = -(f11 + f22 + 2.0 * f12) * (h1 * h2);
            let fi = (j - 1) * m + i;
            a[fi] += f.x;
            a[free + fi] += f.y;
            a[2 * free + fi] += f.z;
        }
    }
}

fn tissue_position(
    input: &ForceInput<'_>,
    scratch: &mut ForceScratch,
    lambda: f32,
    x: &[f32],
    a: &mut [f32],
) {
    let s = input.springs;
    let ns = s.len();
    resize3(&mut scratch.spring_dir, ns);
    resize3(&mut scratch.anchor_vel, ns);
    scratch.spring_pos.resize(ns, 0.0);
    let free = x.len() / 3;
    let kin = input.kin;
    let inv_h = if kin.h_s > 0.0 {
        (1.0 / kin.h_s) as f32
    } else {
        0.0
    };
    let inv_mass = &input.materials.inv_mass;
    for q in 0..ns {
        let p = s.point[q] as usize;
        let mut l = [0.0f32; 3];
        for c in 0..3 {
            let (st, en) = (kin.anchors_start[c][q], kin.anchors_end[c][q]);
            let anchor = st + lambda * (en - st);
            scratch.anchor_vel[c][q] = (en - st) * inv_h;
            l[c] = x[c * free + p] - anchor;
        }
        let len = (l[0] * l[0] + l[1] * l[1] + l[2] * l[2]).sqrt();
        if len > s.rest_m[q] && len > 0.0 {
            let inv = 1.0 / len;
            let pull = s.ks[q] * (len - s.rest_m[q]);
            scratch.spring_pos[q] = pull;
            let k = pull * inv_mass[p];
            for c in 0..3 {
                let d = l[c] * inv;
                scratch.spring_dir[c][q] = d;
                a[c * free + p] -= k * d;
            }
        } else {
            scratch.spring_pos[q] = 0.0;
            for c in 0..3 {
                scratch.spring_dir[c][q] = 0.0;
            }
        }
    }
}

/// `a += M⁻¹ f_velocity(t, x, v)`: global damping and the tissue damping term (the total spring
/// pull is clamped at zero: the springs only ever pull, eq. 3).
pub fn add_velocity_accel(
    input: &ForceInput<'_>,
    scratch: &ForceScratch,
    v: &[f32],
    a: &mut [f32],
) {
    let mat = input.materials;
    let free = v.len() / 3;
    for c in 0..3 {
        let ac = &mut a[c * free..(c + 1) * free];
        let vc = &v[c * free..(c + 1) * free];
        for ((ai, vi), d) in ac.iter_mut().zip(vc).zip(&mat.damping_per_mass) {
            *ai -= d * vi;
        }
    }
    let s = input.springs;
    for q in 0..s.len() {
        let pos = scratch.spring_pos[q];
        let slack = scratch.spring_dir[0][q] == 0.0
            && scratch.spring_dir[1][q] == 0.0
            && scratch.spring_dir[2][q] == 0.0;
        if slack {
            continue;
        }
        let p = s.point[q] as usize;
        let mut ldot_dir = 0.0;
        for c in 0..3 {
            ldot_dir += (v[c * free + p] - scratch.anchor_vel[c][q]) * scratch.spring_dir[c][q];
        }
        let total = (pos + s.kd[q] * ldot_dir).max(0.0);
        let k = (total - pos) * mat.inv_mass[p];
        for c in 0..3 {
            a[c * free + p] -= k * scratch.spring_dir[c][q];
        }
    }
}

/// Kinetic energy of a free-point velocity state, joules.
pub fn kinetic_energy(materials: &Materials, v: &[f32]) -> f64 {
    let free = v.len() / 3;
    let mut e = 0.0f64;
    for c in 0..3 {
        let vc = &v[c * free..(c + 1) * free];
        let mut s = 0.0f32;
        for (vi, m) in vc.iter().zip(&materials.mass_kg) {
            s += m * vi * vi;
        }
        e += f64::from(s);
    }
    0.5 * e
}
