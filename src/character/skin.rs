//! The skin layer: an M×N elastic surface mesh with per-point material values, and the fat
//! thickness under each point.
//!
//! # Grid and material coordinates
//! `around` = M points around the body (periodic: point `i = M` is point `0`), `along` = N rows
//! from the bottom boundary (row 0) to the top boundary (row N−1). Point `(i, j)` is stored at
//! index `j·M + i` in every per-point array ([`Skin::index`]). Material coordinates are
//! `u₁ = i/M ∈ [0, 1)` around and `u₂ = j/(N−1) ∈ [0, 1]` along, so grid spacings are
//! `h₁ = 1/M`, `h₂ = 1/(N−1)` ([`Skin::spacing`]) and metric values do not depend on the
//! resolution.
//!
//! # Boundaries
//! Rows 0 and N−1 are fixed: their points move rigidly with [`Skin::bottom_joint`] and
//! [`Skin::top_joint`]; their positions in those joints' frames are [`Skin::bottom_ring_m`] and
//! [`Skin::top_ring_m`]. [`Skin::positions_m`] holds every point (boundary rows included) in the
//! world at the skeleton's neutral posture.
//!
//! # Orientation
//! Points are ordered so that `∂r/∂u₂ × ∂r/∂u₁` points out of the body ([`Skin::outward_normals`]).

use glam::Vec3;

use super::skeleton::{JointId, Skeleton};

/// A symmetric 2×2 tensor stored as `[t₁₁, t₁₂, t₂₂]` (used for G⁰, η and ξ).
pub type Sym2 = [f32; 3];

/// Whether `t` is positive definite (what a rest metric must be): `t₁₁ > 0`, `t₂₂ > 0` and a
/// positive determinant. False for any NaN component.
pub fn is_positive_definite(t: &Sym2) -> bool {
    t[0] > 0.0 && t[2] > 0.0 && t[0] * t[2] - t[1] * t[1] > 0.0
}

/// Node strides `(around, along)` of [`Skin::fat_normals`] on an `around × along` skin: the
/// fewest nodes that span at least one spacing of a 32×32 skin, `⌈points / 32⌉` in each
/// direction (at least 1, around at most half the ring). With one-node differences a 128×128
/// torso's fat points jumped by millimetres from step to step as wrinkles turned the normals
/// (557 constraint rejections and 209 forced steps in 1 s of its motion; with these strides 1
/// and 1). Rounding down instead left skins between multiples of 32 with one-node normals over
/// less than that spacing: the 40×40 and 48×48 wombats built at their resolutions had over a
/// hundred constraint rejections in 2 s at rest (none with these strides).
pub fn fat_normal_stride(around: usize, along: usize) -> (usize, usize) {
    (
        around.div_ceil(32).clamp(1, (around / 2).max(1)),
        along.div_ceil(32).max(1),
    )
}

/// The elastic skin surface (see the module docs for grid, frames and orientation).
#[derive(Debug, Clone, PartialEq)]
pub struct Skin {
    /// M: points around (periodic), at least 3.
    pub around: u32,
    /// N: rows along, at least 3 (rows 0 and N−1 are fixed to joints).
    pub along: u32,
    /// Joint that carries row 0.
    pub bottom_joint: JointId,
    /// Joint that carries row N−1.
    pub top_joint: JointId,
    /// Row 0 in `bottom_joint`'s frame, metres (M points).
    pub bottom_ring_m: Vec<Vec3>,
    /// Row N−1 in `top_joint`'s frame, metres (M points).
    pub top_ring_m: Vec<Vec3>,
    /// Every point in the world at the neutral posture, metres (M·N points). The initial state
    /// of a simulation.
    pub positions_m: Vec<Vec3>,
    /// Lumped mass of each point, kg. Mass density per unit material area is
    /// `mass_kg / (h₁·h₂)`.
    pub mass_kg: Vec<f32>,
    /// Damping coefficient γ of each point (force −γ·v, eq. 5), N·s/m.
    pub damping_n_s_per_m: Vec<f32>,
    /// Rest metric G⁰ `[g₁₁, g₁₂, g₂₂]` at each point, m² per unit material coordinate²
    /// (the preferred size of the skin; see [`Skin::metric_at`] for the discretisation).
    pub rest_metric: Vec<Sym2>,
    /// Stretch (η₁₁, η₂₂) and shear (η₁₂) elasticity `[η₁₁, η₁₂, η₂₂]`, N/m³ (energy density
    /// per material area per (m²)²).
    pub stretch: Vec<Sym2>,
    /// Bending/twist resistance ξ `[ξ₁₁, ξ₁₂, ξ₂₂]` (0 allowed), N/m (energy density per
    /// material area per m² of curvature form).
    pub bending: Vec<Sym2>,
    /// Fat thickness τ under each point, metres (≥ 0). Constraints act on `r − τ·n̂` (eq. 6).
    pub fat_m: Vec<f32>,
}

impl Skin {
    /// Most points a skin may have (M·N), 1024×1024. The simulation takes about 0.9 kB per
    /// point (900 MB at this size, measured on the torso), so a much larger skin would abort
    /// in the allocator on an ordinary machine instead of failing with a message; and at 20 M
    /// point-steps per second a step of this size already takes 50 ms.
    pub const MAX_POINTS: u64 = 1 << 20;

    /// Number of points, M·N.
    pub fn point_count(&self) -> usize {
        self.around as usize * self.along as usize
    }

    /// Index of point `(i around, j along)`; `i` wraps around.
    #[inline]
    pub fn index(&self, i: u32, j: u32) -> usize {
        (j as usize) * (self.around as usize) + (i % self.around.max(1)) as usize
    }

    /// `(i around, j along)` of an index.
    #[inline]
    pub fn grid_of(&self, index: usize) -> (u32, u32) {
        let m = self.around.max(1) as usize;
        ((index % m) as u32, (index / m) as u32)
    }

    /// True for points of the fixed rows 0 and N−1.
    #[inline]
    pub fn is_fixed(&self, index: usize) -> bool {
        let (_, j) = self.grid_of(index);
        j == 0 || j + 1 == self.along
    }

    /// Material grid spacings `(h₁, h₂) = (1/M, 1/(N−1))`.
    pub fn spacing(&self) -> (f32, f32) {
        (
            1.0 / self.around.max(1) as f32,
            1.0 / (self.along.max(2) - 1) as f32,
        )
    }

    /// The metric G `[g₁₁, g₁₂, g₂₂]` of `positions` at point `(i, j)` by forward differences
    /// (`D⁺₁ r = (r[i+1,j] − r[i,j])/h₁`, periodic; `D⁺₂ r = (r[i,j+1] − r[i,j])/h₂`, the last
    /// row using the backward difference). This is how rest metrics in example files are made.
    pub fn metric_at(&self, positions: &[Vec3], i: u32, j: u32) -> Sym2 {
        let (h1, h2) = self.spacing();
        let p = positions[self.index(i, j)];
        let d1 = (positions[self.index(i + 1, j)] - p) / h1;
        let d2 = if j + 1 < self.along {
            (positions[self.index(i, j + 1)] - p) / h2
        } else {
            (p - positions[self.index(i, j - 1)]) / h2
        };
        [d1.dot(d1), d1.dot(d2), d2.dot(d2)]
    }

    /// The metric of `positions` at every point (see [`Skin::metric_at`]).
    pub fn metric_of(&self, positions: &[Vec3]) -> Vec<Sym2> {
        let mut out = Vec::with_capacity(self.point_count());
        for j in 0..self.along {
            for i in 0..self.around {
                out.push(self.metric_at(positions, i, j));
            }
        }
        out
    }

    /// Unit outward normals of `positions` (central differences around, one-sided at the fixed
    /// rows), written into `out` (resized to M·N). A degenerate point (a zero or non-finite
    /// cross product) gets +Y.
    pub fn outward_normals(&self, positions: &[Vec3], out: &mut Vec<Vec3>) {
        self.strided_outward_normals(positions, (1, 1), out);
    }

    /// The normals that offset the fat points `r − τ·n̂` (eq. 6): [`Skin::outward_normals`]
    /// with differences over [`fat_normal_stride`] nodes, so that a skin finer than 32 points
    /// in a direction offsets its fat along the shape of a 32×32 skin's neighbourhood and not
    /// along every wrinkle. The simulator offsets its fat points along these same normals; at
    /// 32×32 and coarser they are the outward normals.
    pub fn fat_normals(&self, positions: &[Vec3], out: &mut Vec<Vec3>) {
        let stride = fat_normal_stride(self.around as usize, self.along as usize);
        self.strided_outward_normals(positions, (stride.0 as u32, stride.1 as u32), out);
    }

    /// Unit outward normals from the differences `r[i+sᵢ, j] − r[i−sᵢ, j]` (periodic) and
    /// `r[i, j+sⱼ] − r[i, j−sⱼ]` (clamped to the fixed rows), `(sᵢ, sⱼ) = stride`.
    fn strided_outward_normals(&self, positions: &[Vec3], stride: (u32, u32), out: &mut Vec<Vec3>) {
        out.clear();
        let (m, n) = (self.around, self.along);
        let (si, sj) = (stride.0.max(1), stride.1.max(1));
        for j in 0..n {
            let (jp, jm) = ((j + sj).min(n - 1), j.saturating_sub(sj));
            for i in 0..m {
                let d1 = positions[self.index(i + si, j)] - positions[self.index(i + m - si, j)];
                let d2 = positions[self.index(i, jp)] - positions[self.index(i, jm)];
                let nrm = d2.cross(d1);
                let len = nrm.length();
                if len > 1e-12 && len.is_finite() {
                    out.push(nrm / len);
                } else {
                    out.push(Vec3::Y);
                }
            }
        }
    }

    /// Mean of the points of row `j` (the ring's centre).
    pub fn ring_center(&self, positions: &[Vec3], j: u32) -> Vec3 {
        let mut c = Vec3::ZERO;
        for i in 0..self.around {
            c += positions[self.index(i, j)];
        }
        c / self.around.max(1) as f32
    }

    /// Checks internal consistency (array lengths, positive and finite values, joints exist).
    /// `Err` names the first problem found.
    pub fn validate(&self, skeleton: &Skeleton) -> Result<(), String> {
        if self.around < 3 || self.along < 3 {
            return Err(format!(
                "skin: resolution must be at least 3×3, got {}×{}",
                self.around, self.along
            ));
        }
        let points = u64::from(self.around) * u64::from(self.along);
        if points > Self::MAX_POINTS {
            return Err(format!(
                "skin: resolution {}×{} is {points} points, more than the {} (1024×1024) a skin may have",
                self.around,
                self.along,
                Self::MAX_POINTS
            ));
        }
        for (name, joint) in [
            ("bottom_joint", self.bottom_joint),
            ("top_joint", self.top_joint),
        ] {
            if joint.index() >= skeleton.len() {
                return Err(format!(
                    "skin: {name} refers to joint {} but the skeleton has {} joints",
                    joint.0,
                    skeleton.len()
                ));
            }
        }
        let m = self.around as usize;
        let mn = self.point_count();
        let check_len = |name: &str, len: usize, want: usize| {
            check_len(name, len, want, self.around, self.along)
        };
        check_len("bottom_ring_m", self.bottom_ring_m.len(), m)?;
        check_len("top_ring_m", self.top_ring_m.len(), m)?;
        check_len("positions_m", self.positions_m.len(), mn)?;
        check_len("mass_kg", self.mass_kg.len(), mn)?;
        check_len("damping_n_s_per_m", self.damping_n_s_per_m.len(), mn)?;
        check_len("rest_metric", self.rest_metric.len(), mn)?;
        check_len("stretch", self.stretch.len(), mn)?;
        check_len("bending", self.bending.len(), mn)?;
        check_len("fat_m", self.fat_m.len(), mn)?;
        let vec_ok = |name: &str, v: &[Vec3]| match v.iter().position(|p| !p.is_finite()) {
            Some(k) => Err(format!("skin: {name}[{k}] is not finite")),
            None => Ok(()),
        };
        vec_ok("bottom_ring_m", &self.bottom_ring_m)?;
        vec_ok("top_ring_m", &self.top_ring_m)?;
        vec_ok("positions_m", &self.positions_m)?;
        let scalars_ok = |name: &str, v: &[f32], strictly_positive: bool| {
            for (k, x) in v.iter().enumerate() {
                if !x.is_finite() {
                    return Err(format!("skin: {name}[{k}] is not finite"));
                }
                if strictly_positive && *x <= 0.0 {
                    return Err(format!("skin: {name}[{k}] must be > 0, got {x}"));
                }
                if !strictly_positive && *x < 0.0 {
                    return Err(format!("skin: {name}[{k}] must be >= 0, got {x}"));
                }
            }
            Ok(())
        };
        scalars_ok("mass_kg", &self.mass_kg, true)?;
        scalars_ok("damping_n_s_per_m", &self.damping_n_s_per_m, false)?;
        scalars_ok("fat_m", &self.fat_m, false)?;
        for (k, g) in self.rest_metric.iter().enumerate() {
            if !g.iter().all(|x| x.is_finite()) {
                return Err(format!("skin: rest_metric[{k}] is not finite"));
            }
            if !is_positive_definite(g) {
                return Err(format!(
                    "skin: rest_metric[{k}] = {g:?} is not positive definite"
                ));
            }
        }
        for (name, v) in [("stretch", &self.stretch), ("bending", &self.bending)] {
            for (k, t) in v.iter().enumerate() {
                if !t.iter().all(|x| x.is_finite() && *x >= 0.0) {
                    return Err(format!("skin: {name}[{k}] = {t:?} must be finite and >= 0"));
                }
            }
        }
        Ok(())
    }
}

/// Checks that the skin array `name` has `want` values (per point, or per ring point) for a
/// skin of `around × along` points; the error names the array, both counts and the resolution.
pub(crate) fn check_len(
    name: &str,
    len: usize,
    want: usize,
    around: u32,
    along: u32,
) -> Result<(), String> {
    if len == want {
        Ok(())
    } else {
        Err(format!(
            "skin: {name} has {len} values, expected {want} (resolution {around}×{along})"
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::character::examples::build;

    /// A `m × n` tube of radius `0.1 m` along +Y whose rings are ordered so the normals point
    /// out, with a wrinkle around of amplitude `wrinkle_m` and a period of four nodes.
    fn wrinkled_tube(m: u32, n: u32, wrinkle_m: f32) -> Vec<Vec3> {
        let mut out = Vec::new();
        for j in 0..n {
            for i in 0..m {
                let a = std::f32::consts::TAU * i as f32 / m as f32;
                let r = 0.1 + wrinkle_m * [0.0, 1.0, 0.0, -1.0][i as usize % 4];
                out.push(Vec3::new(r * a.cos(), 0.01 * j as f32, r * a.sin()));
            }
        }
        out
    }

    #[test]
    fn fat_normals_are_the_outward_normals_up_to_32_points() {
        for (m, n) in [(32, 32), (16, 16), (32, 9)] {
            let skin = build("penguin", m, n).expect("example").skin;
            let (mut outward, mut fat) = (Vec::new(), Vec::new());
            skin.outward_normals(&skin.positions_m, &mut outward);
            skin.fat_normals(&skin.positions_m, &mut fat);
            assert_eq!(outward, fat, "{m}x{n}");
        }
    }

    #[test]
    fn fat_normals_of_a_fine_skin_do_not_follow_a_wrinkle_of_a_few_nodes() {
        let skin = build("penguin", 64, 64).expect("example").skin;
        assert_eq!(fat_normal_stride(64, 64), (2, 2));
        let tube = wrinkled_tube(64, 64, 0.002);
        let (mut outward, mut fat) = (Vec::new(), Vec::new());
        skin.outward_normals(&tube, &mut outward);
        skin.fat_normals(&tube, &mut fat);
        let (mut worst_outward, mut worst_fat) = (1.0f32, 1.0f32);
        for j in 1..63 {
            for i in 0..64 {
                let k = skin.index(i, j);
                let radial = Vec3::new(tube[k].x, 0.0, tube[k].z).normalize();
                worst_outward = worst_outward.min(outward[k].dot(radial));
                worst_fat = worst_fat.min(fat[k].dot(radial));
            }
        }
        // Half the points' neighbours differ by 4 mm over 2 cm: tilted by about 0.2 rad. Two
        // nodes away the wrinkle is at the same height on both sides.
        assert!(
            worst_outward < 0.995,
            "outward normals follow it: {worst_outward}"
        );
        assert!(worst_fat > 0.9999, "fat normals are radial: {worst_fat}");
    }

    #[test]
    fn fat_normal_strides_stay_within_the_grid() {
        assert_eq!(fat_normal_stride(3, 3), (1, 1));
        assert_eq!(fat_normal_stride(32, 16), (1, 1));
        assert_eq!(fat_normal_stride(33, 63), (2, 2));
        assert_eq!(fat_normal_stride(64, 128), (2, 4));
        assert_eq!(fat_normal_stride(65, 96), (3, 3));
        assert_eq!(fat_normal_stride(1024, 5), (32, 1));
        assert_eq!(fat_normal_stride(40, 1000), (2, 32));
        assert_eq!(fat_normal_stride(1, 1), (1, 1));
    }
}
