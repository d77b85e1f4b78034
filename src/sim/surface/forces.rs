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

use std::ops::Range;

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
    /// Full-grid positions, SoA: filled by the position evaluation only when the bending pass
    /// needs them (callers of [`assemble_grid`], e.g. the constraint phase, may use it as their
    /// grid buffer).
    pub grid: [Vec<f32>; 3],
    /// Rows 0, 1, N−2 and N−1 of the last position evaluation ([`edge_rows`]).
    edges: [Vec<f32>; 3],
    /// Stretch fluxes F₁, F₂ at the nodes of rows 0..N−2.
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
    /// Per spring: 1/mass of its point (filled only when the springs are not one contiguous
    /// run of points; a run reads the materials' slice).
    spring_inv_mass: Vec<f32>,
    /// Per spring: its point's position or velocity (gathered for the vector pass).
    spring_point: [Vec<f32>; 3],
    /// Per spring: the acceleration it subtracts from its point (scattered after the pass).
    spring_accel: [Vec<f32>; 3],
    /// The springs' [`contiguous_run`] as found by the last position evaluation, with the
    /// address and length of the springs' point list and the free point count it was found for.
    spring_run: Option<(usize, usize, usize, Option<usize>)>,
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

/// The grid's two first and two last rows (SoA, `4M` points: row 0, row 1, row N−2, row N−1):
/// the fixed rows interpolated at `lambda` with exactly [`assemble_grid`]'s operations, the
/// free rows copied from `x`. Rows 1..N−2 are read from `x` itself, these carry the stencils
/// that reach a fixed row.
fn edge_rows(
    m: usize,
    x: &[f32],
    rings_start: &[Vec<f32>; 3],
    rings_end: &[Vec<f32>; 3],
    lambda: f32,
    out: &mut [Vec<f32>; 3],
) {
    resize3(out, 4 * m);
    let free = x.len() / 3;
    for c in 0..3 {
        let (rs, re) = (&rings_start[c][..2 * m], &rings_end[c][..2 * m]);
        let xc = &x[c * free..(c + 1) * free];
        let o = &mut out[c];
        let (bottom, rest) = o.split_at_mut(m);
        let (free_rows, top) = rest.split_at_mut(2 * m);
        for ((o, s), e) in bottom.iter_mut().zip(&rs[..m]).zip(&re[..m]) {
            *o = s + lambda * (e - s);
        }
        for ((o, s), e) in top.iter_mut().zip(&rs[m..]).zip(&re[m..]) {
            *o = s + lambda * (e - s);
        }
        free_rows[..m].copy_from_slice(&xc[..m]);
        free_rows[m..].copy_from_slice(&xc[free - m..]);
    }
}

/// Unit outward normals on the full grid (central differences around, one-sided along at the
/// fixed rows; `∂r/∂u₂ × ∂r/∂u₁`), SoA. Degenerate points get +Y.
pub fn grid_normals(around: usize, along: usize, grid: &[Vec<f32>; 3], out: &mut [Vec<f32>; 3]) {
    let m = around;
    resize3(out, m * along);
    if m < 2 || along < 2 || grid.iter().any(|g| g.len() != m * along) {
        return; // not a grid of this size (a programming error; callers never do so)
    }
    normals_pass(m, along, grid, out);
}

/// Unit outward normals on the full grid like [`grid_normals`], but from differences over
/// `stride` nodes each way (wrapping around, clamped along), SoA. With a stride of 1 it is
/// [`grid_normals`]. Every node gets exactly `normal_node_strided`'s value (the stride around
/// first limited to `M/2`), computed in vector runs (see `strided_normals_pass`).
pub fn grid_normals_strided(
    around: usize,
    along: usize,
    stride: (usize, usize),
    grid: &[Vec<f32>; 3],
    out: &mut [Vec<f32>; 3],
) {
    let (si, sj) = (stride.0.max(1), stride.1.max(1));
    if si == 1 && sj == 1 {
        grid_normals(around, along, grid, out);
        return;
    }
    let m = around;
    resize3(out, m * along);
    if m < 2 || along < 2 || grid.iter().any(|g| g.len() != m * along) {
        return;
    }
    strided_normals_pass(m, along, si.min(m / 2).max(1), sj, grid, out);
}

/// [`grid_normals_strided`] at the listed nodes only (grid indices `j · M + i`; others out of
/// range are skipped), with the same value at each: for passes that read the normals of a few
/// nodes (the constraint re-checks). The other entries of `out` are left as they are, and
/// `out` must already have one entry per node.
pub fn grid_normals_strided_at(
    around: usize,
    along: usize,
    stride: (usize, usize),
    grid: &[Vec<f32>; 3],
    nodes: impl IntoIterator<Item = usize>,
    out: &mut [Vec<f32>; 3],
) {
    let m = around;
    let len = m * along;
    if m < 2 || along < 2 || grid.iter().chain(out.iter()).any(|g| g.len() != len) {
        return;
    }
    let stride = (stride.0.max(1).min(m / 2).max(1), stride.1.max(1));
    for k in nodes.into_iter().filter(|&k| k < len) {
        let n = normal_node_strided(m, along, grid, k % m, k / m, stride);
        out[0][k] = n[0];
        out[1][k] = n[1];
        out[2][k] = n[2];
    }
}

/// The normals of the `len` nodes from `o` on: node `o + k` from the differences
/// `g[a + k] − g[b + k]` (around) and `g[c + k] − g[d + k]` (along) with `[a, b, c, d] = src`,
/// as [`unit_normal`] does for one node. The slices are cut to one length so the loop has no
/// bounds checks and vectorizes.
#[inline(always)]
fn normals_run(
    grid: &[Vec<f32>; 3],
    out: &mut [Vec<f32>; 3],
    o: usize,
    len: usize,
    src: [usize; 4],
) {
    #[inline(always)]
    fn sl(v: &[Vec<f32>; 3], o: usize, len: usize) -> [&[f32]; 3] {
        [&v[0][o..o + len], &v[1][o..o + len], &v[2][o..o + len]]
    }
    let (ip, im) = (sl(grid, src[0], len), sl(grid, src[1], len));
    let (jp, jm) = (sl(grid, src[2], len), sl(grid, src[3], len));
    let [ox, oy, oz] = out;
    let (ox, oy, oz) = (
        &mut ox[o..o + len],
        &mut oy[o..o + len],
        &mut oz[o..o + len],
    );
    for k in 0..len {
        let n = unit_normal(
            [
                ip[0][k] - im[0][k],
                ip[1][k] - im[1][k],
                ip[2][k] - im[2][k],
            ],
            [
                jp[0][k] - jm[0][k],
                jp[1][k] - jm[1][k],
                jp[2][k] - jm[2][k],
            ],
        );
        ox[k] = n[0];
        oy[k] = n[1];
        oz[k] = n[2];
    }
}

crate::sim::simd::multiversion! {
    /// [`grid_normals_strided`]' work for strides `1 ≤ si ≤ M/2` around and `sj ≥ 1` along,
    /// node by node the same operations as [`normal_node_strided`], in runs of consecutive
    /// nodes ([`normals_run`]): the rows `sj ≤ j ≤ N−1−sj`, whose neighbours along are not
    /// clamped, as one flat run (the nodes within `si` of a row's ends first take nodes of the
    /// neighbouring rows around); each clamped end row's columns `si ≤ i < M−si`; then the `si`
    /// columns at each end of every row, whose neighbours around wrap.
    fn strided_normals_pass(
        m: usize,
        along: usize,
        si: usize,
        sj: usize,
        grid: &[Vec<f32>; 3],
        out: &mut [Vec<f32>; 3]
    ) {
        // Rows `first..end` have both neighbours `sj` rows away.
        let (first, end) = (sj, along.saturating_sub(sj));
        if end > first {
            let (o, d) = (first * m, sj * m);
            normals_run(grid, out, o, (end - first) * m, [o + si, o - si, o + d, o - d]);
        }
        let inner = m - 2 * si; // columns whose neighbours around do not wrap
        for j in (0..first.min(along)).chain(end.max(first)..along) {
            let (rp, rm) = ((j + sj).min(along - 1) * m, j.saturating_sub(sj) * m);
            let o = j * m + si;
            normals_run(grid, out, o, inner, [o + si, o - si, rp + si, rm + si]);
        }
        for j in 0..along {
            let (rp, rm) = ((j + sj).min(along - 1) * m, j.saturating_sub(sj) * m);
            let r = j * m;
            // `i < si`: `i − si` wraps to `i + M − si`; `i ≥ M − si`: `i + si` to `i + si − M`.
            normals_run(grid, out, r, si, [r + si, r + m - si, rp, rm]);
            let e = m - si;
            normals_run(grid, out, r + e, si, [r, r + e - si, rp + e, rm + e]);
        }
    }
}

/// [`unit_normal`] of the differences `g[a] − g[b]` (around) and `g[c] − g[d]` (along).
#[inline(always)]
fn normal_at(g: &[Vec<f32>; 3], a: usize, b: usize, c: usize, d: usize) -> [f32; 3] {
    unit_normal(
        [g[0][a] - g[0][b], g[1][a] - g[1][b], g[2][a] - g[2][b]],
        [g[0][c] - g[0][d], g[1][c] - g[1][d], g[2][c] - g[2][d]],
    )
}

/// The normal at node `(i, j)` from the grid, by the definition (wrap around, one-sided ends).
#[inline(always)]
fn normal_node(m: usize, along: usize, g: &[Vec<f32>; 3], i: usize, j: usize) -> [f32; 3] {
    normal_node_strided(m, along, g, i, j, (1, 1))
}

/// The normal at node `(i, j)` from differences over `stride` nodes (around, along), wrapping
/// around and clamped along (`stride.0 < m`).
#[inline(always)]
fn normal_node_strided(
    m: usize,
    along: usize,
    g: &[Vec<f32>; 3],
    i: usize,
    j: usize,
    stride: (usize, usize),
) -> [f32; 3] {
    let (si, sj) = stride;
    let jp = (j + sj).min(along - 1);
    let jm = j.saturating_sub(sj);
    let ip = (i + si) % m;
    let im = (i + m - si) % m;
    normal_at(g, j * m + ip, j * m + im, jp * m + i, jm * m + i)
}

/// `normalize(d2 × d1)`, or +Y when that is degenerate (tiny or not finite).
#[inline(always)]
fn unit_normal(d1: [f32; 3], d2: [f32; 3]) -> [f32; 3] {
    let nx = d2[1] * d1[2] - d2[2] * d1[1];
    let ny = d2[2] * d1[0] - d2[0] * d1[2];
    let nz = d2[0] * d1[1] - d2[1] * d1[0];
    let len2 = nx * nx + ny * ny + nz * nz;
    // `len2 ≤ f32::MAX` is false for +∞ and NaN.
    let ok = len2 > 1e-24 && len2 <= f32::MAX;
    let inv = 1.0 / len2.sqrt();
    if ok {
        [nx * inv, ny * inv, nz * inv]
    } else {
        [0.0, 1.0, 0.0]
    }
}

crate::sim::simd::multiversion! {
    /// [`grid_normals`]' work: the interior rows as one flat vector loop (a row's first and
    /// last nodes first take the neighbouring rows' nodes around), then the wrapped columns
    /// and the two end rows by the definition.
    fn normals_pass(m: usize, along: usize, grid: &[Vec<f32>; 3], out: &mut [Vec<f32>; 3]) {
        if along >= 3 {
            let len = m * (along - 2);
            #[inline(always)]
            fn sl(v: &[Vec<f32>; 3], o: usize, len: usize) -> [&[f32]; 3] {
                [&v[0][o..o + len], &v[1][o..o + len], &v[2][o..o + len]]
            }
            let (ip, im) = (sl(grid, m + 1, len), sl(grid, m - 1, len));
            let (jp, jm) = (sl(grid, 2 * m, len), sl(grid, 0, len));
            let [ox, oy, oz] = out;
            let (ox, oy, oz) = (&mut ox[m..m + len], &mut oy[m..m + len], &mut oz[m..m + len]);
            for k in 0..len {
                let n = unit_normal(
                    [ip[0][k] - im[0][k], ip[1][k] - im[1][k], ip[2][k] - im[2][k]],
                    [jp[0][k] - jm[0][k], jp[1][k] - jm[1][k], jp[2][k] - jm[2][k]],
                );
                ox[k] = n[0];
                oy[k] = n[1];
                oz[k] = n[2];
            }
        }
        // (No closure here: it would not be inlined into the AVX2 copy.)
        for j in 1..along.saturating_sub(1) {
            for i in [0, m - 1] {
                let n = normal_node(m, along, grid, i, j);
                out[0][j * m + i] = n[0];
                out[1][j * m + i] = n[1];
                out[2][j * m + i] = n[2];
            }
        }
        for j in [0, along - 1] {
            for i in 0..m {
                let n = normal_node(m, along, grid, i, j);
                out[0][j * m + i] = n[0];
                out[1][j * m + i] = n[1];
                out[2][j * m + i] = n[2];
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
    if m < 2 || n < 3 || x.len() != 3 * free || a.len() != 3 * free {
        return; // not a state of this skin (a programming error; the model never calls so)
    }
    let lambda = input.lambda(t_s);
    let kin = input.kin;
    let mat = input.materials;
    // The fixed rows at λ; the free rows are read from `x` itself (no grid is assembled
    // unless the bending pass needs one).
    edge_rows(
        m,
        x,
        &kin.rings_start,
        &kin.rings_end,
        lambda,
        &mut scratch.edges,
    );
    if mat.has_bending {
        assemble_grid(
            m,
            n,
            x,
            &kin.rings_start,
            &kin.rings_end,
            lambda,
            &mut scratch.grid,
        );
    }
    resize3(&mut scratch.flux1, m * (n - 1));
    resize3(&mut scratch.flux2, m * (n - 1));
    // Elastic stretch/shear, scaled by 1/m, plus gravity: writes every entry of `a`.
    stretch_accel(
        m,
        n,
        x,
        &scratch.edges,
        &mat.eta,
        &mat.rest_metric,
        &mat.inv_mass,
        [mat.gravity.x, mat.gravity.y, mat.gravity.z],
        &mut scratch.flux1,
        &mut scratch.flux2,
        a,
    );
    if mat.has_bending {
        elastic_bending(input, scratch, a);
    }
    tissue_position(input, scratch, lambda, x, a);
}

/// The stretch fluxes at one node from its position `p`, its neighbour around `p1` and along
/// `q` (see the module docs): `[F₁x, F₁y, F₁z, F₂x, F₂y, F₂z]`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn flux_at(
    p: [f32; 3],
    p1: [f32; 3],
    q: [f32; 3],
    eta: [f32; 3],
    rest: [f32; 3],
    inv_h1: f32,
    inv_h2: f32,
) -> [f32; 6] {
    let a1 = [
        (p1[0] - p[0]) * inv_h1,
        (p1[1] - p[1]) * inv_h1,
        (p1[2] - p[2]) * inv_h1,
    ];
    let a2 = [
        (q[0] - p[0]) * inv_h2,
        (q[1] - p[1]) * inv_h2,
        (q[2] - p[2]) * inv_h2,
    ];
    let gg11 = a1[0] * a1[0] + a1[1] * a1[1] + a1[2] * a1[2];
    let gg12 = a1[0] * a2[0] + a1[1] * a2[1] + a1[2] * a2[2];
    let gg22 = a2[0] * a2[0] + a2[1] * a2[1] + a2[2] * a2[2];
    let al11 = eta[0] * (gg11 - rest[0]);
    let al12 = eta[1] * (gg12 - rest[1]);
    let al22 = eta[2] * (gg22 - rest[2]);
    [
        al11 * a1[0] + al12 * a2[0],
        al11 * a1[1] + al12 * a2[1],
        al11 * a1[2] + al12 * a2[2],
        al12 * a1[0] + al22 * a2[0],
        al12 * a1[1] + al22 * a2[1],
        al12 * a1[2] + al22 * a2[2],
    ]
}

/// Fluxes at the `len` consecutive nodes from `o` (stored there) of a grid run `g` (each
/// component at least `len + M` long): node `k` at `g[k]`, its neighbour around at `g[k + 1]`
/// and along at `g[k + M]`, as [`flux_at`] does for one ([`flux_pass`]).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn flux_run(
    g: [&[f32]; 3],
    m: usize,
    eta: &[Vec<f32>; 3],
    rest: &[Vec<f32>; 3],
    inv_h: [f32; 2],
    o: usize,
    len: usize,
    f1: &mut [Vec<f32>; 3],
    f2: &mut [Vec<f32>; 3],
) {
    #[inline(always)]
    fn sl(v: &[Vec<f32>; 3], o: usize, len: usize) -> [&[f32]; 3] {
        [&v[0][o..o + len], &v[1][o..o + len], &v[2][o..o + len]]
    }
    let (e, r) = (sl(eta, o, len), sl(rest, o, len));
    let [f1x, f1y, f1z] = f1;
    let [f2x, f2y, f2z] = f2;
    flux_pass(
        &g[0][..len + m],
        &g[1][..len + m],
        &g[2][..len + m],
        m,
        e[0],
        e[1],
        e[2],
        r[0],
        r[1],
        r[2],
        inv_h[0],
        inv_h[1],
        &mut f1x[o..o + len],
        &mut f1y[o..o + len],
        &mut f1z[o..o + len],
        &mut f2x[o..o + len],
        &mut f2y[o..o + len],
        &mut f2z[o..o + len],
    );
}

crate::sim::simd::multiversion! {
    /// [`flux_at`] over a run of nodes (the length `len` of `f1x`; `g` is `len + m` long): node
    /// `k` at `g[k]`, its neighbours at `g[k + 1]` and `g[k + m]`. Each array is its own
    /// argument, so the compiler knows the outputs alias nothing and vectorizes the loop without
    /// run-time checks.
    fn flux_pass(
        gx: &[f32],
        gy: &[f32],
        gz: &[f32],
        m: usize,
        ex: &[f32],
        ey: &[f32],
        ez: &[f32],
        rx: &[f32],
        ry: &[f32],
        rz: &[f32],
        inv_h1: f32,
        inv_h2: f32,
        f1x: &mut [f32],
        f1y: &mut [f32],
        f1z: &mut [f32],
        f2x: &mut [f32],
        f2y: &mut [f32],
        f2z: &mut [f32],
    ) {
        let len = f1x.len();
        if gx.len() < len + m || gy.len() < len + m || gz.len() < len + m || m == 0 {
            return;
        }
        let (px, py, pz) = (&gx[..len], &gy[..len], &gz[..len]);
        let (p1x, p1y, p1z) = (&gx[1..len + 1], &gy[1..len + 1], &gz[1..len + 1]);
        let (qx, qy, qz) = (&gx[m..m + len], &gy[m..m + len], &gz[m..m + len]);
        let (ex, ey, ez) = (&ex[..len], &ey[..len], &ez[..len]);
        let (rx, ry, rz) = (&rx[..len], &ry[..len], &rz[..len]);
        let (f1y, f1z) = (&mut f1y[..len], &mut f1z[..len]);
        let (f2x, f2y, f2z) = (&mut f2x[..len], &mut f2y[..len], &mut f2z[..len]);
        for k in 0..len {
            let f = flux_at(
                [px[k], py[k], pz[k]],
                [p1x[k], p1y[k], p1z[k]],
                [qx[k], qy[k], qz[k]],
                [ex[k], ey[k], ez[k]],
                [rx[k], ry[k], rz[k]],
                inv_h1,
                inv_h2,
            );
            f1x[k] = f[0];
            f1y[k] = f[1];
            f1z[k] = f[2];
            f2x[k] = f[3];
            f2y[k] = f[4];
            f2z[k] = f[5];
        }
    }
}

crate::sim::simd::multiversion! {
    /// Stretch/shear accelerations plus gravity on every free point (module docs): fluxes at
    /// the nodes of rows 0..N−2, then `a = h₁h₂ (D⁻₁F₁ + D⁻₂F₂)/m + g`. The grid is read in
    /// place: rows 1..N−2 from the free state `x`, rows 0 and N−1 from `edges` (rows 0, 1, N−2
    /// and N−1 of the evaluation, [`edge_rows`]). The fluxes run as three long vector loops
    /// (row 0, rows 1..N−3, row N−2; a row's last node first takes the next row's first as its
    /// neighbour around), then the wrapped column is recomputed; the accelerations as one loop
    /// over the flattened free rows.
    #[allow(clippy::too_many_arguments)]
    fn stretch_accel(
        m: usize,
        n: usize,
        x: &[f32],
        edges: &[Vec<f32>; 3],
        eta: &[Vec<f32>; 3],
        rest: &[Vec<f32>; 3],
        inv_mass: &[f32],
        gravity: [f32; 3],
        f1: &mut [Vec<f32>; 3],
        f2: &mut [Vec<f32>; 3],
        a: &mut [f32],
    ) {
        let nodes = m * (n - 1);
        let free = m * (n - 2);
        let inv_h = [m as f32, (n - 1) as f32];
        let (h1, h2) = (1.0 / inv_h[0], 1.0 / inv_h[1]);
        let xb = [&x[..free], &x[free..2 * free], &x[2 * free..3 * free]];
        let eb = [&edges[0][..4 * m], &edges[1][..4 * m], &edges[2][..4 * m]];
        #[inline(always)]
        fn from(v: [&[f32]; 3], o: usize) -> [&[f32]; 3] {
            [&v[0][o..], &v[1][o..], &v[2][o..]]
        }
        // Row 0 (nodes 0..M) on rows 0 and 1 of `edges`.
        flux_run(eb, m, eta, rest, inv_h, 0, m, f1, f2);
        // Rows 1..N−3 (nodes M..M(N−2)): all three in `x`.
        let inner = m * (n - 3);
        flux_run(xb, m, eta, rest, inv_h, m, inner, f1, f2);
        // Row N−2 on rows N−2 and N−1 of `edges`.
        flux_run(from(eb, 2 * m), m, eta, rest, inv_h, m + inner, m, f1, f2);
        // The wrapped column: node (M−1, j) with its neighbour around (0, j) and along
        // (M−1, j + 1); rows 0 and N−2 from `edges`, the rows between from `x`.
        #[inline(always)]
        #[allow(clippy::too_many_arguments)]
        fn wrapped(
            g: [&[f32]; 3],
            i: usize,
            i1: usize,
            iq: usize,
            k: usize,
            eta: &[Vec<f32>; 3],
            rest: &[Vec<f32>; 3],
            inv_h: [f32; 2],
            f1: &mut [Vec<f32>; 3],
            f2: &mut [Vec<f32>; 3],
        ) {
            let f = flux_at(
                [g[0][i], g[1][i], g[2][i]],
                [g[0][i1], g[1][i1], g[2][i1]],
                [g[0][iq], g[1][iq], g[2][iq]],
                [eta[0][k], eta[1][k], eta[2][k]],
                [rest[0][k], rest[1][k], rest[2][k]],
                inv_h[0],
                inv_h[1],
            );
            for c in 0..3 {
                f1[c][k] = f[c];
                f2[c][k] = f[3 + c];
            }
        }
        wrapped(eb, m - 1, 0, 2 * m - 1, m - 1, eta, rest, inv_h, f1, f2);
        for j in 1..n - 2 {
            let r = (j - 1) * m;
            wrapped(xb, r + m - 1, r, r + 2 * m - 1, j * m + m - 1, eta, rest, inv_h, f1, f2);
        }
        let k = (n - 2) * m + m - 1;
        wrapped(eb, 3 * m - 1, 2 * m, 4 * m - 1, k, eta, rest, inv_h, f1, f2);
        // force = h₁h₂ (D⁻₁F₁ + D⁻₂F₂) = h₂ (F₁[k] − F₁[k−e₁]) + h₁ (F₂[k] − F₂[k−M]), at grid
        // node k = f + M of free point f; column 0 takes F₁ of its row's last node after.
        let im = &inv_mass[..free];
        for c in 0..3 {
            let out = &mut a[c * free..(c + 1) * free];
            let (f1c, f2c) = (&f1[c][..nodes], &f2[c][..nodes]);
            let g = gravity[c];
            for (((((o, f1k), f1m), f2k), f2m), imk) in out
                .iter_mut()
                .zip(&f1c[m..])
                .zip(&f1c[m - 1..])
                .zip(&f2c[m..])
                .zip(&f2c[..free])
                .zip(im)
            {
                *o = (h2 * (f1k - f1m) + h1 * (f2k - f2m)) * imk + g;
            }
            for j in 1..n - 1 {
                let (f, k) = ((j - 1) * m, j * m);
                out[f] = (h2 * (f1c[k] - f1c[k + m - 1]) + h1 * (f2c[k] - f2c[k - m])) * im[f] + g;
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
            let im = mat.inv_mass[fi];
            a[fi] += f.x * im;
            a[free + fi] += f.y * im;
            a[2 * free + fi] += f.z * im;
        }
    }
}

/// `Some(o)` when spring `q` sits on free point `o + q` for every `q` (one spring per point of
/// a run, the usual layout): its points' values are then plain slices of the state.
fn contiguous_run(point: &[u32], free: usize) -> Option<usize> {
    let first = *point.first()? as usize;
    if first + point.len() > free {
        return None;
    }
    let mut expected = first as u32;
    let mut ok = true;
    for p in point {
        ok &= *p == expected;
        expected = expected.wrapping_add(1);
    }
    ok.then_some(first)
}

/// The three blocks `[x…, y…, z…]` of a state of `free` points.
pub(super) fn blocks(state: &[f32], free: usize) -> [&[f32]; 3] {
    block_slices(state, free, 0, free)
}

/// [`blocks`], mutable.
pub(super) fn blocks_mut(state: &mut [f32], free: usize) -> [&mut [f32]; 3] {
    let (x, rest) = state[..3 * free].split_at_mut(free);
    let (y, z) = rest.split_at_mut(free);
    [x, y, z]
}

/// The three blocks of `state` restricted to points `o..o + len`.
fn block_slices(state: &[f32], free: usize, o: usize, len: usize) -> [&[f32]; 3] {
    [
        &state[o..o + len],
        &state[free + o..free + o + len],
        &state[2 * free + o..2 * free + o + len],
    ]
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
    scratch.spring_inv_mass.resize(ns, 0.0);
    if ns == 0 {
        return;
    }
    let free = x.len() / 3;
    let kin = input.kin;
    let inv_h = if kin.h_s > 0.0 {
        (1.0 / kin.h_s) as f32
    } else {
        0.0
    };
    let inv_mass = &input.materials.inv_mass;
    let run = contiguous_run(&s.point, free);
    scratch.spring_run = Some((s.point.as_ptr() as usize, ns, free, run));
    if run.is_none() {
        for (im, p) in scratch.spring_inv_mass.iter_mut().zip(&s.point) {
            *im = inv_mass[*p as usize];
        }
        resize3(&mut scratch.spring_point, ns);
        resize3(&mut scratch.spring_accel, ns);
        gather_points(&s.point, x, free, &mut scratch.spring_point);
        for acc in &mut scratch.spring_accel {
            acc.fill(0.0);
        }
    }
    let ForceScratch {
        spring_point,
        spring_accel,
        anchor_vel,
        spring_dir,
        spring_pos,
        spring_inv_mass,
        ..
    } = scratch;
    let points: [&[f32]; 3];
    let accel: [&mut [f32]; 3];
    let spring_inv_mass: &[f32] = match run {
        Some(o) => &inv_mass[o..o + ns],
        None => spring_inv_mass,
    };
    match run {
        Some(o) => {
            points = block_slices(x, free, o, ns);
            let (ax, rest) = a.split_at_mut(free);
            let (ay, az) = rest.split_at_mut(free);
            accel = [&mut ax[o..o + ns], &mut ay[o..o + ns], &mut az[o..o + ns]];
        }
        None => {
            points = [&spring_point[0], &spring_point[1], &spring_point[2]];
            let [sx, sy, sz] = spring_accel;
            accel = [&mut sx[..], &mut sy[..], &mut sz[..]];
        }
    }
    tissue_position_pass(
        &kin.anchors_start,
        &kin.anchors_end,
        lambda,
        inv_h,
        points,
        &s.rest_m,
        &s.ks,
        spring_inv_mass,
        anchor_vel,
        spring_dir,
        spring_pos,
        accel,
    );
    if run.is_none() {
        scatter_add(&s.point, &scratch.spring_accel, free, a);
    }
}

/// `out[c][q] = state[c·free + point[q]]`.
fn gather_points(point: &[u32], state: &[f32], free: usize, out: &mut [Vec<f32>; 3]) {
    let [ox, oy, oz] = out;
    for (((p, ox), oy), oz) in point.iter().zip(ox.iter_mut()).zip(oy.iter_mut()).zip(oz) {
        let p = *p as usize;
        *ox = state[p];
        *oy = state[free + p];
        *oz = state[2 * free + p];
    }
}

/// `a[c·free + point[q]] += accel[c][q]` (in spring order, so several springs on one point add up
/// as they did one by one).
fn scatter_add(point: &[u32], accel: &[Vec<f32>; 3], free: usize, a: &mut [f32]) {
    let [ax, ay, az] = accel;
    for (((p, ax), ay), az) in point.iter().zip(ax).zip(ay).zip(az) {
        let p = *p as usize;
        a[p] += ax;
        a[free + p] += ay;
        a[2 * free + p] += az;
    }
}

crate::sim::simd::multiversion! {
    /// Position part of the tissue springs (eq. 3), branch-free, on their points' positions
    /// `point` (one per spring): anchor at λ and its velocity, unit direction and pull
    /// `k_s(|l| − l⁰)` of taut springs (zero for slack ones), and `accel −= pull/m · d̂`.
    #[allow(clippy::too_many_arguments)]
    fn tissue_position_pass(
        anchors_start: &[Vec<f32>; 3],
        anchors_end: &[Vec<f32>; 3],
        lambda: f32,
        inv_h: f32,
        point: [&[f32]; 3],
        rest_m: &[f32],
        ks: &[f32],
        inv_mass: &[f32],
        anchor_vel: &mut [Vec<f32>; 3],
        dir: &mut [Vec<f32>; 3],
        pos: &mut [f32],
        accel: [&mut [f32]; 3],
    ) {
        let ns = rest_m.len();
        let (ks, inv_mass, pos) = (&ks[..ns], &inv_mass[..ns], &mut pos[..ns]);
        let st = [&anchors_start[0][..ns], &anchors_start[1][..ns], &anchors_start[2][..ns]];
        let en = [&anchors_end[0][..ns], &anchors_end[1][..ns], &anchors_end[2][..ns]];
        let pt = [&point[0][..ns], &point[1][..ns], &point[2][..ns]];
        let [avx, avy, avz] = anchor_vel;
        let (avx, avy, avz) = (&mut avx[..ns], &mut avy[..ns], &mut avz[..ns]);
        let [dx, dy, dz] = dir;
        let (dx, dy, dz) = (&mut dx[..ns], &mut dy[..ns], &mut dz[..ns]);
        let [acx, acy, acz] = accel;
        let (acx, acy, acz) = (&mut acx[..ns], &mut acy[..ns], &mut acz[..ns]);
        for q in 0..ns {
            let mut l = [0.0f32; 3];
            let mut av = [0.0f32; 3];
            for c in 0..3 {
                let (s, e) = (st[c][q], en[c][q]);
                av[c] = (e - s) * inv_h;
                l[c] = pt[c][q] - (s + lambda * (e - s));
            }
            avx[q] = av[0];
            avy[q] = av[1];
            avz[q] = av[2];
            let len = (l[0] * l[0] + l[1] * l[1] + l[2] * l[2]).sqrt();
            let taut = len > rest_m[q] && len > 0.0;
            let inv = if taut { 1.0 / len } else { 0.0 };
            let pull = if taut { ks[q] * (len - rest_m[q]) } else { 0.0 };
            pos[q] = pull;
            let k = pull * inv_mass[q];
            let d = [l[0] * inv, l[1] * inv, l[2] * inv];
            dx[q] = d[0];
            dy[q] = d[1];
            dz[q] = d[2];
            acx[q] -= k * d[0];
            acy[q] -= k * d[1];
            acz[q] -= k * d[2];
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
    if a.len() != v.len() || mat.damping_per_mass.len() != free {
        return; // not a state of this skin (a programming error; the model never calls so)
    }
    damping_accel(&mat.damping_per_mass, v, a);
    tissue_velocity(input, scratch, v, a);
}

/// `a = a_pos + M⁻¹ f_velocity(t, x, v)`: [`add_velocity_accel`] on a copy of `a_pos` (the
/// position part), with the copy fused into the damping pass; bit-identical to copying and
/// adding.
pub fn velocity_accel_from(
    input: &ForceInput<'_>,
    scratch: &ForceScratch,
    v: &[f32],
    a_pos: &[f32],
    a: &mut [f32],
) {
    let mat = input.materials;
    let free = v.len() / 3;
    if a.len() != v.len() || a_pos.len() != v.len() || mat.damping_per_mass.len() != free {
        if a.len() == a_pos.len() {
            a.copy_from_slice(a_pos);
        }
        return; // not a state of this skin (a programming error; the model never calls so)
    }
    let s = input.springs;
    let ns = s.len();
    let run = if ns == 0 || scratch.spring_pos.len() != ns || scratch.spring_inv_mass.len() != ns {
        None
    } else {
        spring_run(scratch, s, free)
    };
    let Some(o) = run else {
        damping_accel_from(&mat.damping_per_mass, v, a_pos, a);
        tissue_velocity(input, scratch, v, a);
        return;
    };
    // One spring per point of `o..o + ns`: damping alone outside the run, damping and tissue
    // in one pass over it (the same operations in the same order as the two passes).
    let dpm = &mat.damping_per_mass;
    for (points, dofs) in outside_run(free, o, ns) {
        damping_accel_from(
            &dpm[points],
            &v[dofs.clone()],
            &a_pos[dofs.clone()],
            &mut a[dofs],
        );
    }
    let (ax, rest) = a.split_at_mut(free);
    let (ay, az) = rest.split_at_mut(free);
    let sc = scratch;
    damped_tissue_velocity_pass(
        block_slices(v, free, o, ns),
        block_slices(a_pos, free, o, ns),
        &dpm[o..o + ns],
        &sc.anchor_vel,
        &sc.spring_dir,
        &sc.spring_pos,
        &s.kd,
        &mat.inv_mass[o..o + ns],
        [&mut ax[o..o + ns], &mut ay[o..o + ns], &mut az[o..o + ns]],
    );
}

/// The fixed point of the Verlet velocity iteration (LEMAN eq. 7b-g), solved point by point:
/// writes into `v_new` the `v⁺` with `v⁺ = v + h (a_pos + M⁻¹ f_velocity((v + v⁺)/2))`, where
/// `a_pos` is the position part at the step's midpoint (the last [`position_accel`]) and the
/// velocity forces are those of [`add_velocity_accel`] (m/s, SoA blocks like `v`).
///
/// Every velocity force acts on one point alone: the global damping `−(γ/m) w` and the tissue
/// spring's damping along its direction `d̂`, `−(max(pos + k_d (w − v_anchor)·d̂, 0) − pos)/m d̂`
/// at the midpoint velocity `w = (v + v⁺)/2`. So the equation is one per point, linear apart
/// from the spring's clamp at zero pull: with `b = (2v + h a_pos)/(2 + hγ/m)` and
/// `β = h/(2 + hγ/m)` it reads `w = b − β k(u) d̂`, where `k` is the spring term's magnitude
/// and `u = (w − v_anchor)·d̂`; `u` solves `u + β k(u) = (b − v_anchor)·d̂` (one root: `k`
/// never decreases in `u`), on the unclamped branch (`k = (k_d/m) u`) when that branch's root
/// keeps the pull non-negative and on the clamped one (`k = −pos/m`) otherwise. Then
/// `v⁺ = 2w − v`.
///
/// The Verlet iteration starts from this instead of `v_t`, and its own test (eq. 7g) then
/// confirms it in one evaluation where it took four from `v_t` on the examples. Returns
/// false, leaving `v_new` alone, when the springs are not one per point in one contiguous
/// run (the solve above assumes at most one spring per point) or the lengths do not fit.
pub fn midpoint_velocity_fixed_point(
    input: &ForceInput<'_>,
    scratch: &ForceScratch,
    v: &[f32],
    a_pos: &[f32],
    h: f32,
    v_new: &mut [f32],
) -> bool {
    let mat = input.materials;
    let free = mat.damping_per_mass.len();
    let s = input.springs;
    let ns = s.len();
    let sized = v.len() == 3 * free && a_pos.len() == v.len() && v_new.len() == v.len();
    let spring_scratch = scratch.spring_pos.len() == ns
        && scratch.spring_dir.iter().all(|c| c.len() == ns)
        && scratch.anchor_vel.iter().all(|c| c.len() == ns);
    if !sized || !spring_scratch || mat.inv_mass.len() != free || s.kd.len() != ns {
        return false;
    }
    let o = if ns == 0 {
        free
    } else {
        match spring_run(scratch, s, free) {
            Some(o) => o,
            None => return false,
        }
    };
    let dpm = &mat.damping_per_mass;
    for (points, dofs) in outside_run(free, o, ns) {
        damped_fixed_point(
            &dpm[points],
            &v[dofs.clone()],
            &a_pos[dofs.clone()],
            h,
            &mut v_new[dofs],
        );
    }
    if ns > 0 {
        let (nx, rest) = v_new.split_at_mut(free);
        let (ny, nz) = rest.split_at_mut(free);
        let sc = scratch;
        damped_tissue_fixed_point(
            block_slices(v, free, o, ns),
            block_slices(a_pos, free, o, ns),
            &dpm[o..o + ns],
            (&sc.anchor_vel, &sc.spring_dir, &sc.spring_pos),
            (&s.kd, &mat.inv_mass[o..o + ns]),
            h,
            [&mut nx[o..o + ns], &mut ny[o..o + ns], &mut nz[o..o + ns]],
        );
    }
    true
}

crate::sim::simd::multiversion! {
    /// [`midpoint_velocity_fixed_point`] for points without a spring (one block):
    /// `v⁺ = ((2 − hγ/m) v + 2h a_pos)/(2 + hγ/m)`.
    fn damped_fixed_point(
        damping_per_mass: &[f32],
        v: &[f32],
        a_pos: &[f32],
        h: f32,
        v_new: &mut [f32],
    ) {
        let n = damping_per_mass.len().min(v.len()).min(a_pos.len()).min(v_new.len());
        let (dpm, v, a_pos) = (&damping_per_mass[..n], &v[..n], &a_pos[..n]);
        let v_new = &mut v_new[..n];
        for i in 0..n {
            let hc = h * dpm[i];
            v_new[i] = ((2.0 - hc) * v[i] + 2.0 * h * a_pos[i]) / (2.0 + hc);
        }
    }
}

crate::sim::simd::multiversion! {
    /// [`midpoint_velocity_fixed_point`] for the points of a contiguous run of springs (one per
    /// point): `spring` is the springs' anchor velocities, directions and position pulls,
    /// `point` their damping constants `k_d` and their points' `1/m`.
    #[allow(clippy::type_complexity)]
    fn damped_tissue_fixed_point(
        point_v: [&[f32]; 3],
        a_pos: [&[f32]; 3],
        damping_per_mass: &[f32],
        spring: (&[Vec<f32>; 3], &[Vec<f32>; 3], &[f32]),
        point: (&[f32], &[f32]),
        h: f32,
        v_new: [&mut [f32]; 3],
    ) {
        let (anchor_vel, dir, pos) = spring;
        let (kd, inv_mass) = point;
        let ns = pos.len();
        let (kd, inv_mass, dpm) = (&kd[..ns], &inv_mass[..ns], &damping_per_mass[..ns]);
        let pv = [&point_v[0][..ns], &point_v[1][..ns], &point_v[2][..ns]];
        let ap = [&a_pos[0][..ns], &a_pos[1][..ns], &a_pos[2][..ns]];
        let av = [&anchor_vel[0][..ns], &anchor_vel[1][..ns], &anchor_vel[2][..ns]];
        let d = [&dir[0][..ns], &dir[1][..ns], &dir[2][..ns]];
        let [nx, ny, nz] = v_new;
        let (nx, ny, nz) = (&mut nx[..ns], &mut ny[..ns], &mut nz[..ns]);
        for q in 0..ns {
            // Two divisions per point (they cost far more than the products).
            let inv_denom = 1.0 / (2.0 + h * dpm[q]);
            let beta = h * inv_denom;
            let b = [
                (2.0 * pv[0][q] + h * ap[0][q]) * inv_denom,
                (2.0 * pv[1][q] + h * ap[1][q]) * inv_denom,
                (2.0 * pv[2][q] + h * ap[2][q]) * inv_denom,
            ];
            // The root's speed along d̂ relative to the anchor, `u = (w − v_anchor)·d̂`, taken
            // directly (not as a difference of two speeds along d̂, which cancels when the
            // damping is stiff): `u (1 + β k_d/m) = (b − v_anchor)·d̂` on the unclamped branch.
            let rel = (b[0] - av[0][q]) * d[0][q]
                + (b[1] - av[1][q]) * d[1][q]
                + (b[2] - av[2][q]) * d[2][q];
            let kappa = kd[q] * inv_mass[q];
            let u = rel / (1.0 + beta * kappa);
            let pulls = pos[q] + kd[q] * u >= 0.0;
            let k = if pulls { kappa * u } else { -pos[q] * inv_mass[q] };
            let bk = beta * k;
            nx[q] = 2.0 * (b[0] - bk * d[0][q]) - pv[0][q];
            ny[q] = 2.0 * (b[1] - bk * d[1][q]) - pv[1][q];
            nz[q] = 2.0 * (b[2] - bk * d[2][q]) - pv[2][q];
        }
    }
}

/// The free points outside a run of springs `o..o + ns` (one spring per point) and their
/// degrees of freedom in each SoA block (`[x…, y…, z…]` over `free` points): per block, the
/// points before the run and those after it, as `(point range, dof range)`, empty ones left out.
fn outside_run(
    free: usize,
    o: usize,
    ns: usize,
) -> impl Iterator<Item = (Range<usize>, Range<usize>)> {
    (0..3).flat_map(move |c| {
        [(0, o), (o + ns, free)]
            .into_iter()
            .filter(|(lo, hi)| hi > lo)
            .map(move |(lo, hi)| (lo..hi, c * free + lo..c * free + hi))
    })
}

/// The springs' [`contiguous_run`], from the last position evaluation when it was for these
/// springs and this state size.
fn spring_run(scratch: &ForceScratch, springs: &Springs, free: usize) -> Option<usize> {
    match scratch.spring_run {
        Some((ptr, n, f, run))
            if ptr == springs.point.as_ptr() as usize && n == springs.len() && f == free =>
        {
            run
        }
        _ => contiguous_run(&springs.point, free),
    }
}

/// The tissue damping term of [`add_velocity_accel`] (lengths already checked).
fn tissue_velocity(input: &ForceInput<'_>, scratch: &ForceScratch, v: &[f32], a: &mut [f32]) {
    let mat = input.materials;
    let free = v.len() / 3;
    let s = input.springs;
    let ns = s.len();
    if ns == 0 || scratch.spring_pos.len() != ns || scratch.spring_inv_mass.len() != ns {
        return;
    }
    let sc = scratch;
    match spring_run(sc, s, free) {
        Some(o) => {
            let (ax, rest) = a.split_at_mut(free);
            let (ay, az) = rest.split_at_mut(free);
            tissue_velocity_pass(
                block_slices(v, free, o, ns),
                &sc.anchor_vel,
                &sc.spring_dir,
                &sc.spring_pos,
                &s.kd,
                &mat.inv_mass[o..o + ns],
                [&mut ax[o..o + ns], &mut ay[o..o + ns], &mut az[o..o + ns]],
            );
        }
        None => {
            for q in 0..ns {
                let p = s.point[q] as usize;
                let d = [
                    sc.spring_dir[0][q],
                    sc.spring_dir[1][q],
                    sc.spring_dir[2][q],
                ];
                let mut ldot_dir = 0.0;
                for c in 0..3 {
                    ldot_dir += (v[c * free + p] - sc.anchor_vel[c][q]) * d[c];
                }
                let pos = sc.spring_pos[q];
                let total = (pos + s.kd[q] * ldot_dir).max(0.0);
                let k = (total - pos) * sc.spring_inv_mass[q];
                for c in 0..3 {
                    a[c * free + p] -= k * d[c];
                }
            }
        }
    }
}

crate::sim::simd::multiversion! {
    /// `a −= (γ/m) v` on the three blocks.
    fn damping_accel(damping_per_mass: &[f32], v: &[f32], a: &mut [f32]) {
        let free = damping_per_mass.len();
        for (ac, vc) in a.chunks_exact_mut(free).zip(v.chunks_exact(free)) {
            for ((ai, vi), d) in ac.iter_mut().zip(vc).zip(damping_per_mass) {
                *ai -= d * vi;
            }
        }
    }
}

crate::sim::simd::multiversion! {
    /// `a = a_pos − (γ/m) v` on the three blocks.
    fn damping_accel_from(damping_per_mass: &[f32], v: &[f32], a_pos: &[f32], a: &mut [f32]) {
        let free = damping_per_mass.len();
        for ((ac, vc), pc) in a
            .chunks_exact_mut(free)
            .zip(v.chunks_exact(free))
            .zip(a_pos.chunks_exact(free))
        {
            for (((ai, vi), pi), d) in ac.iter_mut().zip(vc).zip(pc).zip(damping_per_mass) {
                *ai = pi - d * vi;
            }
        }
    }
}

/// Spring `q`'s velocity part over its mass: with the pull `max(pos + k_d l̇·d̂, 0)` in place of
/// its position part `pos`, `(total − pos)/m` (multiply by `d̂` and subtract from the point's
/// acceleration). `l̇` is the point's velocity `pv` less the anchor's `av`; `d` is `d̂`.
#[inline(always)]
fn tissue_pull_change(
    pv: [&[f32]; 3],
    av: [&[f32]; 3],
    d: [&[f32]; 3],
    pos: f32,
    kd: f32,
    inv_mass: f32,
    q: usize,
) -> f32 {
    let mut ldot_dir = 0.0;
    for c in 0..3 {
        ldot_dir += (pv[c][q] - av[c][q]) * d[c][q];
    }
    let total = (pos + kd * ldot_dir).max(0.0);
    (total - pos) * inv_mass
}

crate::sim::simd::multiversion! {
    /// [`damping_accel_from`] and then [`tissue_velocity_pass`] on the points of a contiguous
    /// run of springs (one per point), in one pass: `a = a_pos − (γ/m) v`, then
    /// `a −= (total − pos)/m · d̂`.
    #[allow(clippy::too_many_arguments)]
    fn damped_tissue_velocity_pass(
        point_v: [&[f32]; 3],
        a_pos: [&[f32]; 3],
        damping_per_mass: &[f32],
        anchor_vel: &[Vec<f32>; 3],
        dir: &[Vec<f32>; 3],
        pos: &[f32],
        kd: &[f32],
        inv_mass: &[f32],
        accel: [&mut [f32]; 3],
    ) {
        let ns = pos.len();
        let (kd, inv_mass, dpm) = (&kd[..ns], &inv_mass[..ns], &damping_per_mass[..ns]);
        let pv = [&point_v[0][..ns], &point_v[1][..ns], &point_v[2][..ns]];
        let ap = [&a_pos[0][..ns], &a_pos[1][..ns], &a_pos[2][..ns]];
        let av = [&anchor_vel[0][..ns], &anchor_vel[1][..ns], &anchor_vel[2][..ns]];
        let d = [&dir[0][..ns], &dir[1][..ns], &dir[2][..ns]];
        let [acx, acy, acz] = accel;
        let (acx, acy, acz) = (&mut acx[..ns], &mut acy[..ns], &mut acz[..ns]);
        for q in 0..ns {
            let damped = [
                ap[0][q] - dpm[q] * pv[0][q],
                ap[1][q] - dpm[q] * pv[1][q],
                ap[2][q] - dpm[q] * pv[2][q],
            ];
            let k = tissue_pull_change(pv, av, d, pos[q], kd[q], inv_mass[q], q);
            acx[q] = damped[0] - k * d[0][q];
            acy[q] = damped[1] - k * d[1][q];
            acz[q] = damped[2] - k * d[2][q];
        }
    }
}

crate::sim::simd::multiversion! {
    /// Velocity part of the tissue springs on their points' velocities `point_v` (one per
    /// spring): the pull `max(pos + k_d l̇·d̂, 0)` replaces the position part `pos`, so
    /// `accel −= (total − pos)/m · d̂` (nothing for slack springs, whose `d̂` and `pos` are 0).
    #[allow(clippy::too_many_arguments)]
    fn tissue_velocity_pass(
        point_v: [&[f32]; 3],
        anchor_vel: &[Vec<f32>; 3],
        dir: &[Vec<f32>; 3],
        pos: &[f32],
        kd: &[f32],
        inv_mass: &[f32],
        accel: [&mut [f32]; 3],
    ) {
        let ns = pos.len();
        let (kd, inv_mass) = (&kd[..ns], &inv_mass[..ns]);
        let pv = [&point_v[0][..ns], &point_v[1][..ns], &point_v[2][..ns]];
        let av = [&anchor_vel[0][..ns], &anchor_vel[1][..ns], &anchor_vel[2][..ns]];
        let d = [&dir[0][..ns], &dir[1][..ns], &dir[2][..ns]];
        let [acx, acy, acz] = accel;
        let (acx, acy, acz) = (&mut acx[..ns], &mut acy[..ns], &mut acz[..ns]);
        for q in 0..ns {
            let k = tissue_pull_change(pv, av, d, pos[q], kd[q], inv_mass[q], q);
            acx[q] -= k * d[0][q];
            acy[q] -= k * d[1][q];
            acz[q] -= k * d[2][q];
        }
    }
}

/// Kinetic energy of a free-point velocity state, joules.
pub fn kinetic_energy(materials: &Materials, v: &[f32]) -> f64 {
    let free = materials.mass_kg.len();
    if v.len() != 3 * free {
        return f64::NAN;
    }
    guard_scan(materials, v, v, v).kinetic_energy_new_j
}

/// What the step guard needs to know about a candidate state, from one pass over it
/// ([`guard_scan`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GuardScan {
    /// Whether every candidate position and velocity is finite.
    pub finite: bool,
    /// Largest squared candidate speed, m²/s².
    pub max_speed2: f32,
    /// Kinetic energy of the candidate velocities, joules.
    pub kinetic_energy_new_j: f64,
    /// Kinetic energy of the current velocities, joules (NaN when `v_old` is not a state).
    pub kinetic_energy_old_j: f64,
    /// Total mass of the free points, kg.
    pub total_mass_kg: f64,
}

/// One pass over a candidate state (`x_new`, `v_new`) and the current velocities `v_old` (all
/// `[x…, y…, z…]` blocks of the free points) for the step guard. A length mismatch reports a
/// non-finite state.
pub fn guard_scan(materials: &Materials, x_new: &[f32], v_new: &[f32], v_old: &[f32]) -> GuardScan {
    let free = materials.mass_kg.len();
    if x_new.len() != 3 * free || v_new.len() != 3 * free {
        return GuardScan {
            finite: false,
            max_speed2: f32::NAN,
            kinetic_energy_new_j: f64::NAN,
            kinetic_energy_old_j: f64::NAN,
            total_mass_kg: f64::NAN,
        };
    }
    let old_ok = v_old.len() == 3 * free;
    let v_old = if old_ok { v_old } else { v_new };
    let sums = guard_pass(
        &materials.mass_kg,
        blocks(x_new, free),
        blocks(v_new, free),
        blocks(v_old, free),
    );
    GuardScan {
        finite: sums[0].is_finite(),
        max_speed2: sums[0],
        kinetic_energy_new_j: 0.5 * f64::from(sums[1]),
        kinetic_energy_old_j: if old_ok {
            0.5 * f64::from(sums[2])
        } else {
            f64::NAN
        },
        total_mass_kg: f64::from(sums[3]),
    }
}

crate::sim::simd::multiversion! {
    /// `[max |v_new|² (NaN/∞ when any x_new or v_new is not finite), Σ m|v_new|², Σ m|v_old|²,
    /// Σ m]` with [`LANES`](crate::sim::simd::LANES) independent accumulators.
    fn guard_pass(
        mass: &[f32],
        x_new: [&[f32]; 3],
        v_new: [&[f32]; 3],
        v_old: [&[f32]; 3],
    ) -> [f32; 4] {
        use crate::sim::simd::{LANES, MaxLanes};
        let n = mass.len();
        let mut speed = MaxLanes::new();
        let mut ke_new = [0.0f32; LANES];
        let mut ke_old = [0.0f32; LANES];
        let mut total = [0.0f32; LANES];
        #[inline(always)]
        fn one(m: f32, x: [f32; 3], v: [f32; 3], vo: [f32; 3]) -> (f32, f32, f32, f32) {
            let s2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
            let o2 = vo[0] * vo[0] + vo[1] * vo[1] + vo[2] * vo[2];
            // 0·x is ±0 for finite x, NaN otherwise: folds the positions into the check.
            let poison = 0.0 * x[0] + 0.0 * x[1] + 0.0 * x[2];
            (s2 + poison, m * s2, m * o2, m)
        }
        let full = n - n % LANES;
        // Chunked views of one length: `[[f32; LANES]]` slices, so no bounds checks.
        #[inline(always)]
        fn ch(s: &[f32], full: usize) -> &[[f32; LANES]] {
            s[..full].as_chunks::<LANES>().0
        }
        let (mc, xc, vc, oc) = (
            ch(mass, full),
            [ch(x_new[0], full), ch(x_new[1], full), ch(x_new[2], full)],
            [ch(v_new[0], full), ch(v_new[1], full), ch(v_new[2], full)],
            [ch(v_old[0], full), ch(v_old[1], full), ch(v_old[2], full)],
        );
        let chunks = mc.len();
        let (xc, vc, oc) = (
            [&xc[0][..chunks], &xc[1][..chunks], &xc[2][..chunks]],
            [&vc[0][..chunks], &vc[1][..chunks], &vc[2][..chunks]],
            [&oc[0][..chunks], &oc[1][..chunks], &oc[2][..chunks]],
        );
        for c in 0..chunks {
            for l in 0..LANES {
                let (s2, kn, ko, mm) = one(
                    mc[c][l],
                    [xc[0][c][l], xc[1][c][l], xc[2][c][l]],
                    [vc[0][c][l], vc[1][c][l], vc[2][c][l]],
                    [oc[0][c][l], oc[1][c][l], oc[2][c][l]],
                );
                speed.push(l, s2);
                ke_new[l] += kn;
                ke_old[l] += ko;
                total[l] += mm;
            }
        }
        for i in full..n {
            let (s2, kn, ko, mm) = one(
                mass[i],
                [x_new[0][i], x_new[1][i], x_new[2][i]],
                [v_new[0][i], v_new[1][i], v_new[2][i]],
                [v_old[0][i], v_old[1][i], v_old[2][i]],
            );
            speed.push(i, s2);
            ke_new[0] += kn;
            ke_old[0] += ko;
            total[0] += mm;
        }
        [
            speed.finish(),
            ke_new.iter().sum(),
            ke_old.iter().sum(),
            total.iter().sum(),
        ]
    }
}

#[cfg(test)]
mod kernel_tests {
    //! The row-fused, vectorized kernels against the straightforward formulas they replace
    //! (full grid, flux arrays, per-spring branches), on a noisy tube with bending, slack and
    //! taut springs, several springs per point and a mid-step λ.
    use super::*;
    use crate::test_noise::Noise;

    /// The plain evaluation: assemble the grid, fluxes everywhere, divergence, bending,
    /// `a·(1/m) + g`, then springs one by one with branches.
    fn reference(input: &ForceInput<'_>, t_s: f64, x: &[f32], v: &[f32]) -> Vec<f32> {
        let (m, n) = (input.around, input.along);
        let free = m * (n - 2);
        let lambda = input.lambda(t_s);
        let mut scratch = ForceScratch::default();
        let kin = input.kin;
        assemble_grid(
            m,
            n,
            x,
            &kin.rings_start,
            &kin.rings_end,
            lambda,
            &mut scratch.grid,
        );
        let g = &scratch.grid;
        let mat = input.materials;
        let (ih1, ih2) = (m as f32, (n - 1) as f32);
        let (h1, h2) = (1.0 / ih1, 1.0 / ih2);
        let mut f1 = vec![[0.0f32; 3]; m * n];
        let mut f2 = vec![[0.0f32; 3]; m * n];
        for j in 0..n - 1 {
            for i in 0..m {
                let k = j * m + i;
                let k1 = j * m + (i + 1) % m;
                let k2 = k + m;
                let p = [g[0][k], g[1][k], g[2][k]];
                let p1 = [g[0][k1], g[1][k1], g[2][k1]];
                let q = [g[0][k2], g[1][k2], g[2][k2]];
                let eta = [mat.eta[0][k], mat.eta[1][k], mat.eta[2][k]];
                let rest = [
                    mat.rest_metric[0][k],
                    mat.rest_metric[1][k],
                    mat.rest_metric[2][k],
                ];
                let f = flux_at(p, p1, q, eta, rest, ih1, ih2);
                f1[k] = [f[0], f[1], f[2]];
                f2[k] = [f[3], f[4], f[5]];
            }
        }
        let mut a = vec![0.0f32; 3 * free];
        for j in 1..n - 1 {
            for i in 0..m {
                let k = j * m + i;
                let km = j * m + (i + m - 1) % m;
                for c in 0..3 {
                    a[c * free + k - m] =
                        h2 * (f1[k][c] - f1[km][c]) + h1 * (f2[k][c] - f2[k - m][c]);
                }
            }
        }
        let mut bend = vec![0.0f32; 3 * free];
        if mat.has_bending {
            let mut s2 = ForceScratch {
                grid: scratch.grid.clone(),
                ..Default::default()
            };
            // The bending pass adds force/m; recover the force with unit masses below.
            let unit = Materials {
                inv_mass: vec![1.0; free],
                ..mat.clone()
            };
            let inp = ForceInput {
                materials: &unit,
                ..*input
            };
            elastic_bending(&inp, &mut s2, &mut bend);
        }
        let gr = [mat.gravity.x, mat.gravity.y, mat.gravity.z];
        for c in 0..3 {
            for f in 0..free {
                let i = c * free + f;
                a[i] = (a[i] + bend[i]) * mat.inv_mass[f] + gr[c];
            }
        }
        let s = input.springs;
        let inv_h = (1.0 / kin.h_s) as f32;
        for q in 0..s.len() {
            let p = s.point[q] as usize;
            let mut l = [0.0f32; 3];
            let mut av = [0.0f32; 3];
            for c in 0..3 {
                let (st, en) = (kin.anchors_start[c][q], kin.anchors_end[c][q]);
                av[c] = (en - st) * inv_h;
                l[c] = x[c * free + p] - (st + lambda * (en - st));
            }
            let len = (l[0] * l[0] + l[1] * l[1] + l[2] * l[2]).sqrt();
            if len > s.rest_m[q] && len > 0.0 {
                let d = [l[0] / len, l[1] / len, l[2] / len];
                let pos = s.ks[q] * (len - s.rest_m[q]);
                let mut ldot = 0.0;
                for c in 0..3 {
                    ldot += (v[c * free + p] - av[c]) * d[c];
                }
                let total = (pos + s.kd[q] * ldot).max(0.0);
                for c in 0..3 {
                    a[c * free + p] -= total * mat.inv_mass[p] * d[c];
                }
            }
        }
        for c in 0..3 {
            for f in 0..free {
                a[c * free + f] -= mat.damping_per_mass[f] * v[c * free + f];
            }
        }
        a
    }

    struct Case {
        m: usize,
        n: usize,
        materials: Materials,
        springs: Springs,
        kin: StepKinematics,
        x: Vec<f32>,
        v: Vec<f32>,
    }

    fn case(m: usize, n: usize, bending: bool, point: Vec<u32>, seed: u64) -> Case {
        let mut noise = Noise(seed);
        let total = m * n;
        let free = m * (n - 2);
        let tube = |i: usize, j: usize, noise: &mut Noise| {
            let th = i as f32 / m as f32 * std::f32::consts::TAU;
            Vec3::new(0.1 * th.cos(), j as f32 * 0.03, 0.1 * th.sin()) + 0.004 * noise.vec()
        };
        let mut x = vec![0.0f32; 3 * free];
        for j in 1..n - 1 {
            for i in 0..m {
                let p = tube(i, j, &mut noise);
                let f = (j - 1) * m + i;
                x[f] = p.x;
                x[free + f] = p.y;
                x[2 * free + f] = p.z;
            }
        }
        let ring = |noise: &mut Noise| {
            let mut r = [vec![0.0; 2 * m], vec![0.0; 2 * m], vec![0.0; 2 * m]];
            for i in 0..m {
                for (k, j) in [(i, 0), (m + i, n - 1)] {
                    let p = tube(i, j, noise);
                    r[0][k] = p.x;
                    r[1][k] = p.y;
                    r[2][k] = p.z;
                }
            }
            r
        };
        let (rings_start, rings_end) = (ring(&mut noise), ring(&mut noise));
        let v: Vec<f32> = (0..3 * free).map(|_| 0.5 * noise.next()).collect();
        let grid3 = |base: f32, spread: f32, noise: &mut Noise| {
            [0, 1, 2].map(|_| {
                (0..total)
                    .map(|_| base + spread * noise.next())
                    .collect::<Vec<_>>()
            })
        };
        let mass_kg: Vec<f32> = (0..free).map(|_| 0.01 + 0.005 * noise.next()).collect();
        let damping: Vec<f32> = (0..free).map(|_| 0.02 + 0.01 * noise.next()).collect();
        let materials = Materials {
            eta: grid3(2.0, 1.0, &mut noise),
            rest_metric: grid3(0.3, 0.1, &mut noise),
            xi: if bending {
                grid3(1e-3, 5e-4, &mut noise)
            } else {
                [vec![0.0; total], vec![0.0; total], vec![0.0; total]]
            },
            rest_curvature: grid3(0.0, 1.0, &mut noise),
            has_bending: bending,
            inv_mass: mass_kg.iter().map(|m| 1.0 / m).collect(),
            damping_per_mass: damping.iter().zip(&mass_kg).map(|(d, m)| d / m).collect(),
            mass_kg,
            damping,
            fat_m: vec![0.0; free],
            gravity: Vec3::new(0.1, -9.81, 0.2),
        };
        let ns = point.len();
        let anchors = |noise: &mut Noise| {
            let mut an = [vec![0.0; ns], vec![0.0; ns], vec![0.0; ns]];
            for (q, p) in point.iter().enumerate() {
                let p = *p as usize;
                // Near the point: about half the springs end up slack (rest 0.01 m).
                let off = 0.012 * noise.vec();
                for c in 0..3 {
                    an[c][q] = x[c * free + p] + off[c];
                }
            }
            an
        };
        let (anchors_start, anchors_end) = (anchors(&mut noise), anchors(&mut noise));
        let springs = Springs {
            source: (0..ns as u32).collect(),
            ks: (0..ns).map(|_| 50.0 + 20.0 * noise.next()).collect(),
            kd: (0..ns).map(|_| 2.0 + noise.next()).collect(),
            rest_m: vec![0.01; ns],
            shape: vec![0; ns],
            anchor_rest_m: vec![Vec3::ZERO; ns],
            point,
        };
        Case {
            m,
            n,
            materials,
            springs,
            kin: StepKinematics {
                t0_s: 1.0,
                h_s: 0.004,
                rings_start,
                rings_end,
                anchors_start,
                anchors_end,
            },
            x,
            v,
        }
    }

    fn check(c: &Case) {
        let input = ForceInput {
            around: c.m,
            along: c.n,
            materials: &c.materials,
            springs: &c.springs,
            kin: &c.kin,
        };
        let t = 1.0 + 0.3 * 0.004;
        let want = reference(&input, t, &c.x, &c.v);
        let mut scratch = ForceScratch::default();
        // Twice through the same scratch: nothing may depend on what it held before.
        for _ in 0..2 {
            let mut got = vec![f32::NAN; c.x.len()];
            position_accel(&input, &mut scratch, t, &c.x, &mut got);
            // The fused copy (the Verlet iteration's path) gives the same bits as copy + add.
            let mut fused = vec![f32::NAN; c.x.len()];
            velocity_accel_from(&input, &scratch, &c.v, &got, &mut fused);
            add_velocity_accel(&input, &scratch, &c.v, &mut got);
            let bits = |a: &[f32]| a.iter().map(|v| v.to_bits()).collect::<Vec<u32>>();
            assert_eq!(
                bits(&fused),
                bits(&got),
                "velocity_accel_from differs from the copy + add"
            );
            let scale = want.iter().fold(0.0f32, |s, a| s.max(a.abs()));
            assert!(scale > 1.0, "a test with forces in it: {scale}");
            for (i, (g, w)) in got.iter().zip(&want).enumerate() {
                assert!(
                    (g - w).abs() <= 2e-5 * scale,
                    "{}x{}, {} springs, bending {}: dof {i}: kernel {g} vs reference {w} (scale {scale})",
                    c.m,
                    c.n,
                    c.springs.len(),
                    c.materials.has_bending
                );
            }
        }
    }

    #[test]
    fn fused_kernels_match_the_plain_formulas() {
        for (m, n) in [(3, 3), (8, 5), (13, 9), (32, 32)] {
            let free = (m * (n - 2)) as u32;
            // One spring per point (the contiguous fast path), a run in the middle, none.
            check(&case(m, n, false, Vec::new(), 11));
            check(&case(m, n, false, (0..free).collect(), 3));
            check(&case(m, n, true, (0..free).collect(), 5));
            check(&case(m, n, false, (free / 3..free).collect(), 7));
            check(&case(m, n, false, Vec::new(), 11));
            // Scattered, repeated points (the gather/scatter path).
            let scattered: Vec<u32> = (0..2 * free).map(|q| (q * 7 + 3) % free).collect();
            check(&case(m, n, true, scattered, 13));
        }
    }

    /// Largest `|v⁺ − (v + h a((v + v⁺)/2))| / max(|v|, |h a|, |h a_pos|, 1 m/s)` over the
    /// degrees of freedom: how far `v⁺` is from the Verlet velocity iteration's fixed point
    /// (`a_pos` from `position_accel`), relative to the terms the difference is taken of (the
    /// stiff springs and damping make them large, and their rounding with them).
    fn fixed_point_residual(
        input: &ForceInput<'_>,
        scratch: &ForceScratch,
        v: &[f32],
        a_pos: &[f32],
        h: f32,
        v_plus: &[f32],
    ) -> f32 {
        let w: Vec<f32> = v.iter().zip(v_plus).map(|(a, b)| 0.5 * (a + b)).collect();
        let mut a = vec![f32::NAN; v.len()];
        velocity_accel_from(input, scratch, &w, a_pos, &mut a);
        (0..v.len()).fold(0.0f32, |r, i| {
            let terms = v[i]
                .abs()
                .max((h * a[i]).abs())
                .max((h * a_pos[i]).abs())
                .max(1.0);
            r.max((v_plus[i] - (v[i] + h * a[i])).abs() / terms)
        })
    }

    #[test]
    fn the_midpoint_velocity_solve_is_the_verlet_iterations_fixed_point() {
        // Taut springs whose pull the damping leaves positive, and those it clamps to zero.
        let mut branches = (0usize, 0usize);
        for (m, n) in [(3, 3), (8, 5), (13, 9), (32, 32)] {
            let free = (m * (n - 2)) as u32;
            for (point, seed) in [
                ((0..free).collect::<Vec<_>>(), 3),
                ((free / 3..free).collect(), 7),
                (Vec::new(), 11),
            ] {
                let mut c = case(m, n, false, point, seed);
                // Stiff damping: the iteration from v_t contracts by only about h k_d/(2m) ≈ 0.6
                // per evaluation, so a start that is not the fixed point shows.
                for kd in &mut c.springs.kd {
                    *kd *= 4.0;
                }
                let input = ForceInput {
                    around: c.m,
                    along: c.n,
                    materials: &c.materials,
                    springs: &c.springs,
                    kin: &c.kin,
                };
                let t = 1.0 + 0.5 * 0.004;
                let mut scratch = ForceScratch::default();
                let mut a_pos = vec![f32::NAN; c.x.len()];
                position_accel(&input, &mut scratch, t, &c.x, &mut a_pos);
                for h in [0.004f32, 0.016] {
                    let mut v_plus = vec![f32::NAN; c.v.len()];
                    assert!(midpoint_velocity_fixed_point(
                        &input,
                        &scratch,
                        &c.v,
                        &a_pos,
                        h,
                        &mut v_plus
                    ));
                    let residual = fixed_point_residual(&input, &scratch, &c.v, &a_pos, h, &v_plus);
                    // The map's own rounding grows with its Lipschitz constant, about
                    // 1 + h/2 (γ/m + k_d/m): up to 30 here.
                    let stiffest = (0..c.springs.len()).fold(0.0f32, |s, q| {
                        let p = c.springs.point[q] as usize;
                        s.max(c.springs.kd[q] * c.materials.inv_mass[p])
                    });
                    let damping = c
                        .materials
                        .damping_per_mass
                        .iter()
                        .fold(0.0f32, |s, d| s.max(*d));
                    let lipschitz = 1.0 + 0.5 * h * (stiffest + damping);
                    assert!(
                        residual <= 1e-6 * lipschitz,
                        "{m}x{n}, {} springs, h {h}: relative residual {residual} (L {lipschitz})",
                        c.springs.len()
                    );
                    // The paper's first iterate, v + h a(v_t), is far from it (the test can
                    // fail), and the solve takes both branches of the spring's clamp.
                    let mut a = vec![0.0f32; c.v.len()];
                    velocity_accel_from(&input, &scratch, &c.v, &a_pos, &mut a);
                    let first: Vec<f32> = c.v.iter().zip(&a).map(|(v, a)| v + h * a).collect();
                    let far = fixed_point_residual(&input, &scratch, &c.v, &a_pos, h, &first);
                    assert!(far > 100.0 * residual.max(1e-6), "{m}x{n} h {h}: {far}");
                    let sc = &scratch;
                    let ns = c.springs.len();
                    let (mut taut, mut clamped) = (0usize, 0usize);
                    for q in 0..ns {
                        if sc.spring_pos[q] <= 0.0 {
                            continue;
                        }
                        let p = c.springs.point[q] as usize;
                        let mut ldot = 0.0;
                        for k in 0..3 {
                            let w =
                                0.5 * (c.v[k * free as usize + p] + v_plus[k * free as usize + p]);
                            ldot += (w - sc.anchor_vel[k][q]) * sc.spring_dir[k][q];
                        }
                        if sc.spring_pos[q] + c.springs.kd[q] * ldot < 0.0 {
                            clamped += 1;
                        } else {
                            taut += 1;
                        }
                    }
                    branches.0 += taut;
                    branches.1 += clamped;
                }
            }
        }
        assert!(
            branches.0 > 20 && branches.1 > 20,
            "both branches of the clamp: {branches:?}"
        );
        // Several springs on one point: no solve (the iteration starts from v_t).
        let c = case(8, 5, false, vec![0, 0, 1], 5);
        let input = ForceInput {
            around: c.m,
            along: c.n,
            materials: &c.materials,
            springs: &c.springs,
            kin: &c.kin,
        };
        let mut scratch = ForceScratch::default();
        let mut a_pos = vec![0.0f32; c.x.len()];
        position_accel(&input, &mut scratch, 1.0, &c.x, &mut a_pos);
        let mut v_plus = vec![7.0f32; c.v.len()];
        assert!(!midpoint_velocity_fixed_point(
            &input,
            &scratch,
            &c.v,
            &a_pos,
            0.01,
            &mut v_plus
        ));
        assert!(v_plus.iter().all(|&x| x == 7.0));
    }

    #[test]
    fn grid_normals_match_the_definition_everywhere() {
        for (m, n) in [(3usize, 2usize), (5, 3), (32, 32), (13, 7)] {
            let c = case(m, n.max(3), false, Vec::new(), 17);
            let mut grid: [Vec<f32>; 3] = Default::default();
            let k = &c.kin;
            assemble_grid(
                m,
                n.max(3),
                &c.x,
                &k.rings_start,
                &k.rings_end,
                0.3,
                &mut grid,
            );
            let n = n.max(3);
            // A collapsed neighbourhood (degenerate normal) and a NaN.
            for c in 0..3 {
                grid[c][m + 1] = grid[c][m];
                grid[c][m + 2] = grid[c][m];
                grid[c][2 * m] = grid[c][m];
            }
            grid[1][n * m - 1] = f32::NAN;
            let mut out: [Vec<f32>; 3] = Default::default();
            grid_normals(m, n, &grid, &mut out);
            for j in 0..n {
                for i in 0..m {
                    let want = normal_node(m, n, &grid, i, j);
                    let got = [out[0][j * m + i], out[1][j * m + i], out[2][j * m + i]];
                    assert_eq!(got, want, "{m}x{n} node ({i}, {j})");
                    assert!(got.iter().all(|v| v.is_finite()));
                }
            }
        }
    }

    #[test]
    fn strided_normals_see_through_wrinkles_finer_than_the_stride() {
        // A cylinder of radius 0.1 m along +Y, 64 around, with a 2 mm wrinkle of period 4
        // nodes around: one-node differences tilt the normals by the wrinkle's slope, two-node
        // differences span a whole half period and stay radial.
        let (m, n) = (64usize, 12usize);
        let mut grid: [Vec<f32>; 3] = Default::default();
        for j in 0..n {
            for i in 0..m {
                let a = std::f32::consts::TAU * i as f32 / m as f32;
                let r = 0.1 + 0.002 * (std::f32::consts::FRAC_PI_2 * i as f32).sin();
                grid[0].push(r * a.cos());
                grid[1].push(0.05 * j as f32);
                grid[2].push(r * a.sin());
            }
        }
        let worst_tilt = |stride: (usize, usize)| {
            let mut out: [Vec<f32>; 3] = Default::default();
            grid_normals_strided(m, n, stride, &grid, &mut out);
            let mut worst = 0.0f32;
            for j in 1..n - 1 {
                for i in 0..m {
                    let k = j * m + i;
                    let radial = Vec3::new(grid[0][k], 0.0, grid[2][k]).normalize();
                    let got = Vec3::new(out[0][k], out[1][k], out[2][k]);
                    worst = worst.max(got.angle_between(radial));
                }
            }
            worst
        };
        let (one, two) = (worst_tilt((1, 1)), worst_tilt((2, 2)));
        assert!(one > 0.1, "one-node normals follow the wrinkle: {one} rad");
        assert!(two < 0.01, "two-node normals do not: {two} rad");
        // A stride of 1 is the ordinary grid normal.
        let (mut a, mut b): ([Vec<f32>; 3], [Vec<f32>; 3]) = Default::default();
        grid_normals_strided(m, n, (1, 1), &grid, &mut a);
        grid_normals(m, n, &grid, &mut b);
        assert_eq!(a, b);
    }

    /// The strided normals as they were first written: node by node by the definition.
    fn grid_normals_strided_reference(
        m: usize,
        along: usize,
        stride: (usize, usize),
        grid: &[Vec<f32>; 3],
    ) -> [Vec<f32>; 3] {
        let stride = (stride.0.max(1).min(m / 2).max(1), stride.1.max(1));
        let mut out: [Vec<f32>; 3] = Default::default();
        resize3(&mut out, m * along);
        for j in 0..along {
            for i in 0..m {
                let n = normal_node_strided(m, along, grid, i, j, stride);
                let k = j * m + i;
                out[0][k] = n[0];
                out[1][k] = n[1];
                out[2][k] = n[2];
            }
        }
        out
    }

    #[test]
    fn strided_normals_are_bit_identical_to_the_definition() {
        let sizes = [
            (40usize, 37usize),
            (128, 128),
            (33, 9),
            (8, 9),
            (7, 4),
            (5, 3),
            (3, 2),
            (2, 5),
            (9, 2),
        ];
        let strides = [
            (1usize, 1usize),
            (2, 2),
            (4, 4),
            (4, 2),
            (2, 4),
            (3, 5),
            (1, 3),
            (5, 1),
        ];
        let mut noise = Noise(29);
        for (m, n) in sizes {
            // A bumpy, twisted tube: no two normals alike, none along the axes.
            let mut grid: [Vec<f32>; 3] = Default::default();
            for j in 0..n {
                for i in 0..m {
                    let a = std::f32::consts::TAU * i as f32 / m as f32 + 0.1 * j as f32;
                    let r = 0.1 + 0.01 * noise.next();
                    let p =
                        Vec3::new(r * a.cos(), 0.02 * j as f32, r * a.sin()) + 0.002 * noise.vec();
                    grid[0].push(p.x);
                    grid[1].push(p.y);
                    grid[2].push(p.z);
                }
            }
            // A collapsed neighbourhood (degenerate normals) mid-grid and a NaN.
            let k = (n / 2) * m + m / 2;
            for c in 0..3 {
                for d in [
                    k + 1,
                    k + 2,
                    k.saturating_sub(1),
                    k + m,
                    k.saturating_sub(m),
                ] {
                    grid[c][d.min(m * n - 1)] = grid[c][k];
                }
            }
            grid[1][(n - 1) * m / 3] = f32::NAN;
            for stride in strides {
                let want = grid_normals_strided_reference(m, n, stride, &grid);
                // Node by node (every third node, and one out of range): the same bits there,
                // the other entries untouched.
                let mut some: [Vec<f32>; 3] = [0, 1, 2].map(|_| vec![f32::NAN; m * n]);
                grid_normals_strided_at(m, n, stride, &grid, (0..=m * n).step_by(3), &mut some);
                for c in 0..3 {
                    for (k, (g, w)) in some[c].iter().zip(&want[c]).enumerate() {
                        if k % 3 == 0 {
                            assert_eq!(g.to_bits(), w.to_bits(), "{m}x{n} {stride:?} node {k}");
                        } else {
                            assert!(g.is_nan(), "{m}x{n} {stride:?}: node {k} was written");
                        }
                    }
                }
                // Twice through the same output, which starts full of NaN: every node is written.
                let mut got: [Vec<f32>; 3] = [0, 1, 2].map(|_| vec![f32::NAN; m * n]);
                for _ in 0..2 {
                    grid_normals_strided(m, n, stride, &grid, &mut got);
                    for c in 0..3 {
                        for (k, (g, w)) in got[c].iter().zip(&want[c]).enumerate() {
                            assert_eq!(
                                g.to_bits(),
                                w.to_bits(),
                                "{m}x{n} stride {stride:?}: node ({}, {}) component {c}: {g} vs {w}",
                                k % m,
                                k / m
                            );
                            assert!(g.is_finite());
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn contiguous_runs_are_recognised_and_nothing_else() {
        assert_eq!(contiguous_run(&[4, 5, 6], 10), Some(4));
        assert_eq!(contiguous_run(&[0], 1), Some(0));
        assert_eq!(contiguous_run(&[], 10), None);
        assert_eq!(contiguous_run(&[4, 6, 7], 10), None);
        assert_eq!(contiguous_run(&[8, 9, 10], 10), None);
        assert_eq!(contiguous_run(&[3, 3], 10), None);
    }
}
