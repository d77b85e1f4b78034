//! Display refinement of the skin grid: a smooth surface through the simulated points.
//!
//! The simulation samples the skin on an `around × along` grid (periodic around, open along).
//! Drawn as flat triangles, a coarse grid cuts chords through the muscles it rests on: on the
//! 32×32 torso the centres of the shoulder quads lie up to about 5 mm inside the deltoids, and
//! the muscles show through the skin. The display therefore draws the tensor-product uniform
//! Catmull-Rom surface through the grid points, sampled `level` times per grid step: every
//! simulated point stays where it is, and the points in between follow the curvature of their
//! neighbours (for points on a circle the chord's error `O(h²)` drops to `O(h⁴)`).
//!
//! Around, the neighbours wrap. Along, the rows beyond the first and last are extrapolated
//! linearly (`p₋₁ = 2p₀ − p₁`), so the end rows, which are fixed to the skeleton, stay put and
//! the curve is straight there rather than overshooting.
//!
//! This is for display only: the simulation and picking keep the simulated grid. Where a muscle
//! bulges between grid points even the smooth surface passes through it; the app then moves
//! those display points out ([`crate::app::skin_display`]).

use glam::Vec3;

/// How many display samples per grid step a skin with `around` points around gets: enough
/// that the drawn grid has at least 64 columns, at most 4 per step (1 for grids already that
/// fine).
pub fn display_level(around: u32) -> u32 {
    if around == 0 {
        return 1;
    }
    64u32.div_ceil(around).clamp(1, 4)
}

/// The refined grid's size `(around · level, (along − 1) · level + 1)`.
pub fn refined_size(around: u32, along: u32, level: u32) -> (u32, u32) {
    let level = level.max(1);
    (around * level, (along.max(1) - 1) * level + 1)
}

/// Uniform Catmull-Rom weights at `t ∈ [0, 1]` between the middle two of four points.
fn weights(t: f32) -> [f32; 4] {
    let (t2, t3) = (t * t, t * t * t);
    [
        0.5 * (-t3 + 2.0 * t2 - t),
        0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
        0.5 * (-3.0 * t3 + 4.0 * t2 + t),
        0.5 * (t3 - t2),
    ]
}

/// Samples the Catmull-Rom curve through `points` (`closed`: periodic; else open with linear
/// end extrapolation) `level` times per segment, into `out` (cleared first). An open curve of
/// `k` points gives `(k − 1) · level + 1` samples, a closed one `k · level`.
fn refine_curve(points: &[Vec3], closed: bool, level: usize, out: &mut Vec<Vec3>) {
    out.clear();
    let k = points.len();
    if k == 0 {
        return;
    }
    if k == 1 || level <= 1 {
        out.extend_from_slice(points);
        return;
    }
    let at = |i: isize| -> Vec3 {
        if closed {
            points[i.rem_euclid(k as isize) as usize]
        } else if i < 0 {
            2.0 * points[0] - points[1]
        } else if i as usize >= k {
            2.0 * points[k - 1] - points[k - 2]
        } else {
            points[i as usize]
        }
    };
    let segments = if closed { k } else { k - 1 };
    for s in 0..segments {
        let i = s as isize;
        let (p0, p1, p2, p3) = (at(i - 1), at(i), at(i + 1), at(i + 2));
        out.push(p1);
        for step in 1..level {
            let w = weights(step as f32 / level as f32);
            out.push(p0 * w[0] + p1 * w[1] + p2 * w[2] + p3 * w[3]);
        }
    }
    if !closed {
        out.push(points[k - 1]);
    }
}

/// The skin grid `positions` (`around × along`, index `j · around + i`) refined `level` times
/// per grid step in both directions, in the same layout with [`refined_size`] points. Returns
/// the positions unchanged when `level ≤ 1` or the sizes do not fit.
pub fn refine_skin_grid(positions: &[Vec3], around: u32, along: u32, level: u32) -> Vec<Vec3> {
    let (m, n, level) = (around as usize, along as usize, level as usize);
    if level <= 1 || m < 3 || n < 2 || positions.len() != m * n {
        return positions.to_vec();
    }
    let (rm, rn) = (m * level, (n - 1) * level + 1);
    // Around first: each simulated row becomes a refined row.
    let mut rows = Vec::with_capacity(rm * n);
    let mut curve = Vec::with_capacity(rm.max(rn));
    for row in positions.chunks_exact(m) {
        refine_curve(row, true, level, &mut curve);
        rows.extend_from_slice(&curve);
    }
    // Then along, column by column.
    let mut out = vec![Vec3::ZERO; rm * rn];
    let mut column = Vec::with_capacity(n);
    for i in 0..rm {
        column.clear();
        column.extend((0..n).map(|j| rows[j * rm + i]));
        refine_curve(&column, false, level, &mut curve);
        for (j, p) in curve.iter().enumerate() {
            out[j * rm + i] = *p;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A cylinder-like skin: `around` points on circles of radius `r` (varying along), `along`
    /// rows 0.05 m apart.
    fn tube(around: u32, along: u32, r: impl Fn(u32) -> f32) -> Vec<Vec3> {
        let mut p = Vec::new();
        for j in 0..along {
            for i in 0..around {
                let a = std::f32::consts::TAU * i as f32 / around as f32;
                p.push(Vec3::new(r(j) * a.cos(), 0.05 * j as f32, r(j) * a.sin()));
            }
        }
        p
    }

    #[test]
    fn the_simulated_points_stay_where_they_are() {
        let (m, n, level) = (12, 7, 3);
        let p = tube(m, n, |j| 0.1 + 0.01 * j as f32);
        let refined = refine_skin_grid(&p, m, n, level);
        let (rm, rn) = refined_size(m, n, level);
        assert_eq!(refined.len(), (rm * rn) as usize);
        for j in 0..n {
            for i in 0..m {
                let q = refined[((j * level) * rm + i * level) as usize];
                assert!(
                    q.distance(p[(j * m + i) as usize]) < 1e-6,
                    "({i}, {j}) moved"
                );
            }
        }
    }

    #[test]
    fn points_between_follow_the_circle_far_closer_than_chords() {
        // 16 points around a circle of 0.1 m: a chord's midpoint is 1.9 mm inside.
        let (m, n, level, r) = (16, 3, 2, 0.1f32);
        let p = tube(m, n, |_| r);
        let chord_mid = (p[0] + p[1]) * 0.5;
        let chord_gap = r - Vec3::new(chord_mid.x, 0.0, chord_mid.z).length();
        assert!(chord_gap > 1.5e-3, "{chord_gap}");
        let refined = refine_skin_grid(&p, m, n, level);
        let worst = refined
            .iter()
            .map(|q| (Vec3::new(q.x, 0.0, q.z).length() - r).abs())
            .fold(0.0f32, f32::max);
        assert!(
            worst < chord_gap / 20.0,
            "refined points are up to {worst} m off the circle (chords {chord_gap} m)"
        );
    }

    #[test]
    fn a_straight_grid_stays_straight_and_the_ends_do_not_overshoot() {
        let (m, n, level) = (8, 5, 4);
        let p = tube(m, n, |j| 0.1 + 0.02 * j as f32); // a cone: straight along
        let refined = refine_skin_grid(&p, m, n, level);
        let (rm, rn) = refined_size(m, n, level);
        for j in 0..rn {
            let q = refined[(j * rm) as usize]; // the column at angle 0: x = r(y), z = 0
            let expected_r = 0.1 + 0.02 * (q.y / 0.05);
            assert!((q.x - expected_r).abs() < 1e-5, "row {j}: {q}");
            assert!(
                q.y >= -1e-6 && q.y <= 0.05 * (n - 1) as f32 + 1e-6,
                "row {j}: {q}"
            );
        }
    }

    #[test]
    fn levels_and_bad_sizes() {
        assert_eq!(display_level(32), 2);
        assert_eq!(display_level(16), 4);
        assert_eq!(display_level(8), 4);
        assert_eq!(display_level(64), 1);
        assert_eq!(display_level(128), 1);
        assert_eq!(display_level(0), 1);
        let p = tube(8, 4, |_| 0.1);
        assert_eq!(refine_skin_grid(&p, 8, 4, 1), p);
        assert_eq!(refine_skin_grid(&p, 7, 4, 2), p, "size mismatch: unchanged");
        assert_eq!(refined_size(8, 4, 2), (16, 7));
    }
}
