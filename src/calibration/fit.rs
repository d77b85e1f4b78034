//! The screen rectangle from measured corner samples.
//!
//! 1. Per corner: the samples' component-wise median `m`; a sample further than
//!    `max(outlier_factor · median distance to m, outlier_floor_m)` from `m` is rejected (a
//!    robust rule: one gross outlier cannot move the median). The rest are averaged. A corner
//!    whose kept samples still spread over more than `max_corner_spread_m` is an error.
//! 2. At least three corners. An affine fit `p = o + u·A + v·B` over the corners' screen units
//!    (u, v) ∈ {0, 1}² (exact for three corners, least squares for four).
//! 3. Checks: A and B not (nearly) parallel (collinear corners), the corner angle near 90°,
//!    opposite edges of similar length (a corner in other units or touched in the wrong place),
//!    a plausible size.
//! 4. An orthonormal frame: A and B's directions are turned symmetrically in their plane until
//!    perpendicular (`right`, `up`), `normal = right × up`. With the orientation fixed, origin,
//!    width and height are the exact least-squares fit (independent 1-D regressions along
//!    `right`, `up` and `normal`).
//! 5. The residual: RMS distance of the measured corners from the fitted rectangle's corners;
//!    too large is an error (the corners do not form a rectangle).

use super::screen::{Corner, ScreenError, ScreenRect};
use glam::{Mat3, Vec3};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Length units of measured positions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Units {
    /// Metres.
    #[serde(rename = "m")]
    Metres,
    /// Centimetres.
    #[serde(rename = "cm")]
    Centimetres,
    /// Inches.
    #[serde(rename = "in")]
    Inches,
}

impl Units {
    /// Metres per unit.
    pub fn metres_per_unit(self) -> f32 {
        match self {
            Units::Metres => 1.0,
            Units::Centimetres => 0.01,
            Units::Inches => 0.0254,
        }
    }
}

/// Tolerances of the fit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FitOptions {
    /// A sample further than this many times the median distance from the corner's median is
    /// an outlier.
    pub outlier_factor: f32,
    /// ... but never reject a sample closer than this (metres).
    pub outlier_floor_m: f32,
    /// Kept samples of one corner may lie at most this far from their mean (metres).
    pub max_corner_spread_m: f32,
    /// Largest accepted deviation of the corner angle from 90 degrees.
    pub max_angle_error_deg: f32,
    /// Largest accepted ratio between opposite edges (four corners).
    pub max_edge_ratio: f32,
    /// Largest accepted RMS residual (metres).
    pub max_residual_m: f32,
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            outlier_factor: 3.0,
            outlier_floor_m: 0.002,
            max_corner_spread_m: 0.02,
            max_angle_error_deg: 10.0,
            max_edge_ratio: 1.2,
            max_residual_m: 0.02,
        }
    }
}

/// Why no screen could be fitted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    /// Fewer than three corners have samples.
    #[error(
        "need at least three corners (lower_left, lower_right, upper_left, upper_right), got {found}: {names}"
    )]
    TooFewCorners {
        /// How many corners had samples.
        found: usize,
        /// Their names.
        names: String,
    },
    /// A sample is NaN or infinite.
    #[error("corner {corner}: sample {index} is not finite")]
    NotFinite {
        /// The corner.
        corner: Corner,
        /// 0-based sample index.
        index: usize,
    },
    /// The kept samples of a corner are too far apart.
    #[error(
        "corner {corner}: samples spread {spread_m:.4} m from their mean (limit {limit_m} m); was the wand moving, or are the samples from different places?"
    )]
    CornerSpread {
        /// The corner.
        corner: Corner,
        /// Largest distance of a kept sample from the mean.
        spread_m: f32,
        /// The limit.
        limit_m: f32,
    },
    /// The corners lie (nearly) on a line.
    #[error(
        "the corners are (nearly) collinear (edge angle {angle_deg:.2} degrees); were they touched in the prompted order?"
    )]
    Collinear {
        /// Angle between the bottom and left edges.
        angle_deg: f32,
    },
    /// The corner angle is far from 90 degrees.
    #[error(
        "the corners do not make a right angle ({angle_deg:.1} degrees, tolerance {tolerance_deg} degrees); were they touched in the prompted order?"
    )]
    NotRectangular {
        /// Angle between the bottom and left edges.
        angle_deg: f32,
        /// Accepted deviation from 90 degrees.
        tolerance_deg: f32,
    },
    /// Opposite edges differ too much in length.
    #[error(
        "opposite edges differ: {edge_a} {len_a_m:.4} m vs {edge_b} {len_b_m:.4} m (ratio limit {limit}); mixed units or a corner touched in the wrong place?"
    )]
    EdgeMismatch {
        /// First edge's name.
        edge_a: &'static str,
        /// Its length.
        len_a_m: f32,
        /// Opposite edge's name.
        edge_b: &'static str,
        /// Its length.
        len_b_m: f32,
        /// The ratio limit.
        limit: f32,
    },
    /// The fitted rectangle is implausible (size) or invalid.
    #[error("{0}")]
    Screen(#[from] ScreenError),
    /// The corners are too far from any rectangle.
    #[error("the corners are {residual_m:.4} m (RMS) from the best rectangle (limit {limit_m} m)")]
    Residual {
        /// RMS residual.
        residual_m: f32,
        /// The limit.
        limit_m: f32,
    },
}

/// How one corner's samples were used.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CornerReport {
    /// The corner.
    pub corner: Corner,
    /// Mean of the kept samples (world, metres).
    pub measured_m: Vec3,
    /// Samples kept.
    pub kept: usize,
    /// Samples rejected as outliers.
    pub rejected: usize,
    /// Distance from the measured corner to the fitted rectangle's corner.
    pub error_m: f32,
}

/// A fitted screen and how well it fits.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScreenFit {
    /// The rectangle (orthonormal frame).
    pub screen: ScreenRect,
    /// RMS distance of the measured corners from the rectangle's corners (metres).
    pub residual_m: f32,
    /// RMS distance of the measured corners from the rectangle's plane (metres; 0 for three).
    pub non_planarity_m: f32,
    /// Angle between the measured bottom and left edges (degrees), before orthonormalising.
    pub measured_angle_deg: f32,
    /// Per corner, in [`Corner::ALL`] order (missing corners left out).
    pub corners: Vec<CornerReport>,
}

/// Measured samples per corner, metres, world frame.
pub type CornerSamples = BTreeMap<Corner, Vec<Vec3>>;

fn median(mut v: Vec<f32>) -> f32 {
    v.sort_by(f32::total_cmp);
    let n = v.len();
    if n == 0 {
        0.0
    } else if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// The robust mean of one corner's samples: (mean, kept, rejected).
fn robust_corner(
    corner: Corner,
    samples: &[Vec3],
    options: &FitOptions,
) -> Result<(Vec3, usize, usize), FitError> {
    if let Some(index) = samples.iter().position(|p| !p.is_finite()) {
        return Err(FitError::NotFinite { corner, index });
    }
    let m = Vec3::new(
        median(samples.iter().map(|p| p.x).collect()),
        median(samples.iter().map(|p| p.y).collect()),
        median(samples.iter().map(|p| p.z).collect()),
    );
    let dist: Vec<f32> = samples.iter().map(|p| (*p - m).length()).collect();
    let limit = (options.outlier_factor * median(dist.clone())).max(options.outlier_floor_m);
    let kept: Vec<Vec3> = samples
        .iter()
        .zip(&dist)
        .filter(|(_, d)| **d <= limit)
        .map(|(p, _)| *p)
        .collect();
    // The median is within `limit` of at least half the samples, so `kept` is never empty.
    let mean = kept.iter().copied().sum::<Vec3>() / kept.len().max(1) as f32;
    let spread_m = kept
        .iter()
        .map(|p| (*p - mean).length())
        .fold(0.0, f32::max);
    if spread_m > options.max_corner_spread_m {
        return Err(FitError::CornerSpread {
            corner,
            spread_m,
            limit_m: options.max_corner_spread_m,
        });
    }
    Ok((mean, kept.len(), samples.len() - kept.len()))
}

/// Fits the screen rectangle to measured corner samples (metres, world frame).
pub fn fit_screen(samples: &CornerSamples, options: &FitOptions) -> Result<ScreenFit, FitError> {
    let mut measured: Vec<(Corner, Vec3, usize, usize)> = Vec::new();
    for corner in Corner::ALL {
        if let Some(s) = samples.get(&corner).filter(|s| !s.is_empty()) {
            let (mean, kept, rejected) = robust_corner(corner, s, options)?;
            measured.push((corner, mean, kept, rejected));
        }
    }
    if measured.len() < 3 {
        return Err(FitError::TooFewCorners {
            found: measured.len(),
            names: measured
                .iter()
                .map(|m| m.0.name())
                .collect::<Vec<_>>()
                .join(", "),
        });
    }
    let get = |c: Corner| measured.iter().find(|m| m.0 == c).map(|m| m.1);
    if let (Some(ll), Some(lr), Some(ur), Some(ul)) = (
        get(Corner::LowerLeft),
        get(Corner::LowerRight),
        get(Corner::UpperRight),
        get(Corner::UpperLeft),
    ) {
        for (edge_a, len_a_m, edge_b, len_b_m) in [
            ("bottom", (lr - ll).length(), "top", (ur - ul).length()),
            ("left", (ul - ll).length(), "right", (ur - lr).length()),
        ] {
            let ratio = len_a_m.max(len_b_m) / len_a_m.min(len_b_m).max(1e-9);
            if ratio > options.max_edge_ratio {
                return Err(FitError::EdgeMismatch {
                    edge_a,
                    len_a_m,
                    edge_b,
                    len_b_m,
                    limit: options.max_edge_ratio,
                });
            }
        }
    }
    // Affine fit p = o + u A + v B: normal equations (XᵀX) β = Xᵀ P with rows [1, u, v].
    let mut xtx = Mat3::ZERO;
    let mut xtp = [Vec3::ZERO; 3];
    for (corner, p, _, _) in &measured {
        let (u, v) = corner.uv();
        let row = Vec3::new(1.0, u, v);
        xtx += Mat3::from_cols(row * row.x, row * row.y, row * row.z);
        for (k, r) in row.to_array().iter().enumerate() {
            xtp[k] += *p * *r;
        }
    }
    let inv = xtx.inverse();
    let coef = |k: usize| -> Vec3 {
        let r = inv.row(k);
        xtp[0] * r.x + xtp[1] * r.y + xtp[2] * r.z
    };
    let (a, b) = (coef(1), coef(2));
    let (la, lb) = (a.length(), b.length());
    let sin = if la > 0.0 && lb > 0.0 {
        a.cross(b).length() / (la * lb)
    } else {
        0.0
    };
    let angle_deg = if la > 0.0 && lb > 0.0 {
        (a.dot(b) / (la * lb)).clamp(-1.0, 1.0).acos().to_degrees()
    } else {
        0.0
    };
    if !sin.is_finite() || sin < 0.25 {
        return Err(FitError::Collinear { angle_deg });
    }
    if (angle_deg - 90.0).abs() > options.max_angle_error_deg {
        return Err(FitError::NotRectangular {
            angle_deg,
            tolerance_deg: options.max_angle_error_deg,
        });
    }
    // Symmetric orthonormalisation in the plane of A and B.
    let (an, bn) = (a / la, b / lb);
    let s = (an + bn).normalize();
    let d = (an - bn).normalize();
    let right = (s + d).normalize();
    let up = (s - d).normalize();
    let normal = right.cross(up).normalize();
    // Exact least squares for origin, width, height with the frame fixed.
    let regress = |axis: Vec3, param: &dyn Fn(Corner) -> f32| -> (f32, f32) {
        let n = measured.len() as f32;
        let xs: Vec<f32> = measured.iter().map(|m| param(m.0)).collect();
        let ys: Vec<f32> = measured.iter().map(|m| m.1.dot(axis)).collect();
        let mx = xs.iter().sum::<f32>() / n;
        let my = ys.iter().sum::<f32>() / n;
        let sxx: f32 = xs.iter().map(|x| (x - mx) * (x - mx)).sum();
        let sxy: f32 = xs.iter().zip(&ys).map(|(x, y)| (x - mx) * (y - my)).sum();
        let slope = sxy / sxx;
        (my - slope * mx, slope)
    };
    let (o_r, width_m) = regress(right, &|c| c.uv().0);
    let (o_u, height_m) = regress(up, &|c| c.uv().1);
    let o_n = measured.iter().map(|m| m.1.dot(normal)).sum::<f32>() / measured.len() as f32;
    let origin = right * o_r + up * o_u + normal * o_n;
    let screen = ScreenRect::new(origin, origin + right * width_m, origin + up * height_m)?;
    let mut sq = 0.0;
    let mut sq_plane = 0.0;
    let mut corners = Vec::new();
    for (corner, p, kept, rejected) in &measured {
        let error_m = (*p - screen.corner_m(*corner)).length();
        sq += error_m * error_m;
        sq_plane += (p.dot(normal) - o_n).powi(2);
        corners.push(CornerReport {
            corner: *corner,
            measured_m: *p,
            kept: *kept,
            rejected: *rejected,
            error_m,
        });
    }
    let n = measured.len() as f32;
    let residual_m = (sq / n).sqrt();
    if residual_m > options.max_residual_m {
        return Err(FitError::Residual {
            residual_m,
            limit_m: options.max_residual_m,
        });
    }
    Ok(ScreenFit {
        screen,
        residual_m,
        non_planarity_m: (sq_plane / n).sqrt(),
        measured_angle_deg: angle_deg,
        corners,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::test_noise::Noise;

    fn known_screen() -> ScreenRect {
        // A 0.53 x 0.30 m monitor, tilted back 15 degrees and turned 20 degrees, in a tracker
        // frame whose origin is off to the side.
        let rot = glam::Quat::from_rotation_y(0.35) * glam::Quat::from_rotation_x(-0.26);
        ScreenRect::from_center(
            Vec3::new(0.4, 0.9, -0.7),
            rot * Vec3::X,
            rot * Vec3::Y,
            0.53,
            0.30,
        )
        .expect("screen")
    }

    fn noisy(
        screen: &ScreenRect,
        corners: &[Corner],
        n: usize,
        noise_m: f32,
        seed: u64,
    ) -> CornerSamples {
        let mut rng = Noise(seed);
        corners
            .iter()
            .map(|c| {
                let p = screen.corner_m(*c);
                let mut v: Vec<Vec3> = (0..n).map(|_| p + rng.vec() * noise_m).collect();
                // Two gross outliers per corner (the wand slipped 5-8 cm).
                v[3] += Vec3::new(0.05, -0.03, 0.02);
                v[n - 2] += Vec3::new(-0.08, 0.0, 0.01);
                (*c, v)
            })
            .collect()
    }

    #[test]
    fn known_screen_is_recovered_from_noisy_samples() {
        // 20 samples per corner, ±2 mm uniform noise on each axis (RMS 1.15 mm per axis), two
        // gross outliers per corner. Accuracy seen over seeds 1-19: corners 0.06-0.6 mm from
        // the truth, width and height within 0.65 mm, residual 0.1-0.5 mm; asserted: corners,
        // width and height within 1 mm, normal within 0.2 degrees, every outlier rejected.
        let truth = known_screen();
        for seed in 1..20u64 {
            let samples = noisy(&truth, &Corner::ALL, 20, 0.002, seed);
            let fit = fit_screen(&samples, &FitOptions::default()).expect("fit");
            for c in Corner::ALL {
                let e = (fit.screen.corner_m(c) - truth.corner_m(c)).length();
                assert!(e < 0.001, "seed {seed} corner {c}: {e} m");
            }
            let (ew, eh) = (fit.screen.width_m() - 0.53, fit.screen.height_m() - 0.30);
            assert!(ew.abs() < 0.001, "seed {seed}: width error {ew}");
            assert!(eh.abs() < 0.001, "seed {seed}: height error {eh}");
            assert!(
                fit.screen
                    .normal()
                    .angle_between(truth.normal())
                    .to_degrees()
                    < 0.2
            );
            assert!(fit.residual_m < 0.002, "{}", fit.residual_m);
            for r in &fit.corners {
                assert_eq!((r.kept, r.rejected), (18, 2), "seed {seed} {:?}", r.corner);
            }
        }
    }

    #[test]
    fn three_corners_are_enough_and_any_three_work() {
        let truth = known_screen();
        for missing in Corner::ALL {
            let corners: Vec<Corner> = Corner::ALL.into_iter().filter(|c| *c != missing).collect();
            let samples = noisy(&truth, &corners, 10, 0.001, 7);
            let fit = fit_screen(&samples, &FitOptions::default()).expect("fit");
            assert_eq!(fit.corners.len(), 3);
            for c in Corner::ALL {
                let e = (fit.screen.corner_m(c) - truth.corner_m(c)).length();
                assert!(e < 0.002, "missing {missing}, corner {c}: {e}");
            }
        }
    }

    #[test]
    fn orthonormalises_a_skewed_measurement_and_reports_residual() {
        // Exact corners of a parallelogram 2 degrees off square.
        let ll = Vec3::ZERO;
        let lr = Vec3::new(0.5, 0.0, 0.0);
        let ul = Vec3::new(0.3 * (2.0f32).to_radians().sin(), 0.3, 0.0);
        let samples: CornerSamples = [
            (Corner::LowerLeft, vec![ll]),
            (Corner::LowerRight, vec![lr]),
            (Corner::UpperLeft, vec![ul]),
            (Corner::UpperRight, vec![lr + ul]),
        ]
        .into_iter()
        .collect();
        let fit = fit_screen(&samples, &FitOptions::default()).expect("fit");
        assert!((fit.measured_angle_deg - 88.0).abs() < 0.01);
        assert!(fit.screen.right().dot(fit.screen.up()).abs() < 1e-6);
        assert!(
            fit.residual_m > 0.002 && fit.residual_m < 0.01,
            "{}",
            fit.residual_m
        );
        assert!(fit.non_planarity_m < 1e-6);
    }

    #[test]
    fn degenerate_inputs_fail_clearly() {
        let opts = FitOptions::default();
        let truth = known_screen();
        let all = noisy(&truth, &Corner::ALL, 10, 0.001, 3);
        let mut two = all.clone();
        two.remove(&Corner::UpperLeft);
        two.remove(&Corner::UpperRight);
        let e = fit_screen(&two, &opts).expect_err("too few");
        assert!(matches!(e, FitError::TooFewCorners { found: 2, .. }), "{e}");
        assert!(e.to_string().contains("at least three"));
        let mut empty_corner = all.clone();
        empty_corner.insert(Corner::UpperLeft, vec![]);
        empty_corner.remove(&Corner::UpperRight);
        assert!(matches!(
            fit_screen(&empty_corner, &opts),
            Err(FitError::TooFewCorners { .. })
        ));
        // Collinear: three corners on one line.
        let line: CornerSamples = [
            (Corner::LowerLeft, vec![Vec3::ZERO]),
            (Corner::LowerRight, vec![Vec3::X * 0.5]),
            (Corner::UpperLeft, vec![Vec3::X * 0.25 + Vec3::Y * 0.001]),
        ]
        .into_iter()
        .collect();
        let e = fit_screen(&line, &opts).expect_err("collinear");
        assert!(matches!(e, FitError::Collinear { .. }), "{e}");
        // Mixed units: one corner in centimetres.
        let mut mixed = noisy(&truth, &Corner::ALL, 10, 0.0001, 3);
        if let Some(v) = mixed.get_mut(&Corner::UpperRight) {
            v.iter_mut().for_each(|p| *p *= 100.0);
        }
        let e = fit_screen(&mixed, &opts).expect_err("mixed units");
        assert!(matches!(e, FitError::EdgeMismatch { .. }), "{e}");
        assert!(e.to_string().contains("mixed units"), "{e}");
        // Absurd size: everything in millimetres read as metres.
        let mm: CornerSamples = all
            .iter()
            .map(|(c, v)| (*c, v.iter().map(|p| *p * 1000.0).collect()))
            .collect();
        let e = fit_screen(
            &mm,
            &FitOptions {
                max_corner_spread_m: 10.0,
                outlier_floor_m: 2.0,
                max_residual_m: 20.0,
                ..opts
            },
        )
        .expect_err("absurd");
        assert!(
            matches!(e, FitError::Screen(ScreenError::AbsurdSize { .. })),
            "{e}"
        );
        assert!(e.to_string().contains("units"));
        // Wrong order: lower right and upper right swapped (a bow tie).
        let mut swapped = all.clone();
        let (a, b) = (
            swapped[&Corner::UpperRight].clone(),
            swapped[&Corner::LowerRight].clone(),
        );
        swapped.insert(Corner::UpperRight, b);
        swapped.insert(Corner::LowerRight, a);
        let e = fit_screen(&swapped, &opts).expect_err("bow tie");
        assert!(e.to_string().contains("order"), "{e}");
        // Samples all over the place.
        let mut rng = Noise(5);
        let mut scattered = all.clone();
        scattered.insert(
            Corner::LowerLeft,
            (0..10).map(|_| rng.vec() * 0.1).collect(),
        );
        let e = fit_screen(&scattered, &opts).expect_err("spread");
        assert!(
            matches!(
                e,
                FitError::CornerSpread {
                    corner: Corner::LowerLeft,
                    ..
                }
            ),
            "{e}"
        );
        // Not finite.
        let mut nan = all;
        if let Some(v) = nan.get_mut(&Corner::LowerRight) {
            v[4] = Vec3::NAN;
        }
        let e = fit_screen(&nan, &opts).expect_err("nan");
        assert_eq!(
            e,
            FitError::NotFinite {
                corner: Corner::LowerRight,
                index: 4
            }
        );
    }

    /// One sample of the property test below: near a corner of [`known_screen`] (as touched),
    /// anywhere within a tracker's reach, anywhere a finite file may put it, or one fixed point
    /// (every corner the same: the most degenerate input).
    fn any_sample() -> impl Strategy<Value = (u8, [f32; 3])> {
        let kind = prop_oneof![6 => Just(0u8), 1 => Just(1u8), 1 => Just(2u8), 1 => Just(3u8)];
        (kind, [-1.0f32..1.0, -1.0f32..1.0, -1.0f32..1.0])
    }

    fn place(corner: Corner, (kind, r): (u8, [f32; 3])) -> Vec3 {
        let r = Vec3::from_array(r);
        match kind {
            0 => known_screen().corner_m(corner) + r * 0.005,
            1 => r * 2.0,
            2 => r * 1e6,
            _ => Vec3::new(0.1, 0.2, 0.3),
        }
    }

    use proptest::prelude::*;

    proptest! {
        /// Whatever finite samples a corners file or a session gives (all within the ±1e6 m
        /// `leman calibrate --corners` accepts), the fit is a finite screen or a refusal,
        /// never a panic or a NaN: with the default tolerances and with tolerances so loose
        /// that degenerate corners reach the rectangle's own construction.
        #[test]
        fn any_finite_samples_give_a_finite_screen_or_a_refusal(
            corners in proptest::array::uniform4(proptest::option::weighted(
                0.9,
                proptest::collection::vec(any_sample(), 0..6),
            )),
            loose: bool,
        ) {
            let mut samples = CornerSamples::new();
            for (corner, raw) in Corner::ALL.into_iter().zip(&corners) {
                if let Some(raw) = raw {
                    samples.insert(corner, raw.iter().map(|s| place(corner, *s)).collect());
                }
            }
            let options = if loose {
                FitOptions {
                    outlier_factor: 1e9,
                    outlier_floor_m: 1e9,
                    max_corner_spread_m: 1e9,
                    max_angle_error_deg: 90.0,
                    max_edge_ratio: 1e9,
                    max_residual_m: 1e9,
                }
            } else {
                FitOptions::default()
            };
            match fit_screen(&samples, &options) {
                Ok(fit) => {
                    for c in Corner::ALL {
                        prop_assert!(fit.screen.corner_m(c).is_finite(), "{fit:?}");
                    }
                    prop_assert!(fit.screen.width_m() > 0.0 && fit.screen.height_m() > 0.0);
                    prop_assert!(fit.screen.normal().is_finite(), "{fit:?}");
                    prop_assert!(fit.residual_m.is_finite() && fit.residual_m >= 0.0);
                    prop_assert!(fit.non_planarity_m.is_finite());
                    prop_assert!(fit.measured_angle_deg.is_finite());
                    for r in &fit.corners {
                        prop_assert!(r.measured_m.is_finite() && r.error_m.is_finite());
                        let given = samples.get(&r.corner).map_or(0, Vec::len);
                        prop_assert_eq!(r.kept + r.rejected, given);
                        prop_assert!(r.kept > 0);
                    }
                }
                Err(e) => prop_assert!(!e.to_string().is_empty()),
            }
        }
    }
}
