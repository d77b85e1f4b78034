//! The screen rectangle in the world frame: three corners of an exact rectangle (lower left,
//! lower right, upper left, as the viewer sees them), with an orthonormal frame.

use glam::{Mat3, Vec3};
use serde::{Deserialize, Serialize};

/// Which corner of the screen, as the viewer sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Corner {
    /// Lower left (Kooima's `pa`).
    LowerLeft,
    /// Lower right (`pb`).
    LowerRight,
    /// Upper right (`pd`, optional when calibrating).
    UpperRight,
    /// Upper left (`pc`).
    UpperLeft,
}

impl Corner {
    /// All four corners in touching order (around the screen, counter-clockwise as seen).
    pub const ALL: [Corner; 4] = [
        Corner::LowerLeft,
        Corner::LowerRight,
        Corner::UpperRight,
        Corner::UpperLeft,
    ];

    /// The corner's position in screen units: (0, 0) lower left, (1, 1) upper right.
    pub fn uv(self) -> (f32, f32) {
        match self {
            Corner::LowerLeft => (0.0, 0.0),
            Corner::LowerRight => (1.0, 0.0),
            Corner::UpperRight => (1.0, 1.0),
            Corner::UpperLeft => (0.0, 1.0),
        }
    }

    /// The snake_case name used in files and JSON (`lower_left`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Corner::LowerLeft => "lower_left",
            Corner::LowerRight => "lower_right",
            Corner::UpperRight => "upper_right",
            Corner::UpperLeft => "upper_left",
        }
    }
}

impl std::fmt::Display for Corner {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Why a set of corners is not a usable screen rectangle.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ScreenError {
    /// A coordinate is NaN or infinite.
    #[error("screen corner {0} is not finite")]
    NotFinite(Corner),
    /// Width or height is (nearly) zero or outside the plausible range.
    #[error(
        "screen size {width_m:.4} m x {height_m:.4} m is implausible (each side must be {min_m} m to {max_m} m; are the units right?)"
    )]
    AbsurdSize {
        /// Width found.
        width_m: f32,
        /// Height found.
        height_m: f32,
        /// Smallest accepted side.
        min_m: f32,
        /// Largest accepted side.
        max_m: f32,
    },
    /// The right and up edges are not perpendicular.
    #[error(
        "screen edges are not perpendicular: the corner angle is {angle_deg:.2} degrees (tolerance {tolerance_deg} degrees)"
    )]
    NotRectangular {
        /// Angle between the right and up edges.
        angle_deg: f32,
        /// Accepted deviation from 90 degrees.
        tolerance_deg: f32,
    },
}

/// Smallest accepted screen side (5 cm).
pub const MIN_SCREEN_SIDE_M: f32 = 0.05;
/// Largest accepted screen side (10 m: a projection wall).
pub const MAX_SCREEN_SIDE_M: f32 = 10.0;

/// An exact rectangle in the world frame (metres). Built by [`ScreenRect::new`] (which checks
/// it) or by the calibration fit (which orthonormalises measured corners first).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ScreenRect {
    /// Lower-left corner, world frame (Kooima's `pa`).
    pub lower_left_m: Vec3,
    /// Lower-right corner, world frame (`pb`).
    pub lower_right_m: Vec3,
    /// Upper-left corner, world frame (`pc`).
    pub upper_left_m: Vec3,
}

impl ScreenRect {
    /// A rectangle from three corners; they must be finite, of plausible size
    /// ([`MIN_SCREEN_SIDE_M`]..=[`MAX_SCREEN_SIDE_M`]) and perpendicular within 0.5 degrees.
    pub fn new(
        lower_left_m: Vec3,
        lower_right_m: Vec3,
        upper_left_m: Vec3,
    ) -> Result<Self, ScreenError> {
        for (c, p) in [
            (Corner::LowerLeft, lower_left_m),
            (Corner::LowerRight, lower_right_m),
            (Corner::UpperLeft, upper_left_m),
        ] {
            if !p.is_finite() {
                return Err(ScreenError::NotFinite(c));
            }
        }
        let rect = Self {
            lower_left_m,
            lower_right_m,
            upper_left_m,
        };
        check_size(rect.width_m(), rect.height_m())?;
        let cos = (lower_right_m - lower_left_m)
            .normalize()
            .dot((upper_left_m - lower_left_m).normalize());
        let angle_deg = cos.clamp(-1.0, 1.0).acos().to_degrees();
        const TOLERANCE_DEG: f32 = 0.5;
        if (angle_deg - 90.0).abs() > TOLERANCE_DEG {
            return Err(ScreenError::NotRectangular {
                angle_deg,
                tolerance_deg: TOLERANCE_DEG,
            });
        }
        Ok(rect)
    }

    /// A rectangle from its centre, its right and up directions (need not be unit or exactly
    /// perpendicular: `up` is re-orthogonalised against `right`) and its size.
    pub fn from_center(
        center_m: Vec3,
        right: Vec3,
        up: Vec3,
        width_m: f32,
        height_m: f32,
    ) -> Result<Self, ScreenError> {
        check_size(width_m, height_m)?;
        let r = right.normalize_or_zero();
        let u = (up - r * up.dot(r)).normalize_or_zero();
        if r == Vec3::ZERO || u == Vec3::ZERO {
            return Err(ScreenError::NotRectangular {
                angle_deg: 0.0,
                tolerance_deg: 0.5,
            });
        }
        let ll = center_m - r * (width_m * 0.5) - u * (height_m * 0.5);
        Self::new(ll, ll + r * width_m, ll + u * height_m)
    }

    /// The default desktop screen: `width_m` x `height_m`, centred on the world origin in the
    /// plane z = 0, facing +Z (toward the viewer), +Y up.
    pub fn desktop(width_m: f32, height_m: f32) -> Result<Self, ScreenError> {
        Self::from_center(Vec3::ZERO, Vec3::X, Vec3::Y, width_m, height_m)
    }

    /// Upper-right corner (`pd`).
    pub fn upper_right_m(&self) -> Vec3 {
        self.lower_right_m + (self.upper_left_m - self.lower_left_m)
    }

    /// A corner by name.
    pub fn corner_m(&self, corner: Corner) -> Vec3 {
        match corner {
            Corner::LowerLeft => self.lower_left_m,
            Corner::LowerRight => self.lower_right_m,
            Corner::UpperRight => self.upper_right_m(),
            Corner::UpperLeft => self.upper_left_m,
        }
    }

    /// Centre of the rectangle.
    pub fn center_m(&self) -> Vec3 {
        (self.lower_right_m + self.upper_left_m) * 0.5
    }

    /// Width (lower left to lower right), metres.
    pub fn width_m(&self) -> f32 {
        (self.lower_right_m - self.lower_left_m).length()
    }

    /// Height (lower left to upper left), metres.
    pub fn height_m(&self) -> f32 {
        (self.upper_left_m - self.lower_left_m).length()
    }

    /// Unit vector along the bottom edge, to the right (Kooima's `vr`).
    pub fn right(&self) -> Vec3 {
        (self.lower_right_m - self.lower_left_m).normalize()
    }

    /// Unit vector along the left edge, upward (`vu`).
    pub fn up(&self) -> Vec3 {
        (self.upper_left_m - self.lower_left_m).normalize()
    }

    /// Unit normal pointing toward the viewer (`vn = vr × vu`).
    pub fn normal(&self) -> Vec3 {
        self.right().cross(self.up()).normalize()
    }

    /// Rotation whose columns are right, up, normal: `world_from_screen` without translation.
    pub fn world_from_screen_rotation(&self) -> Mat3 {
        Mat3::from_cols(self.right(), self.up(), self.normal())
    }

    /// Signed distance of a world point in front of the screen plane (positive toward the
    /// viewer).
    pub fn distance_in_front_m(&self, p_world: Vec3) -> f32 {
        (p_world - self.lower_left_m).dot(self.normal())
    }

    /// The part of this screen between screen units (u0, v0) (lower left) and (u1, v1) (upper
    /// right), e.g. the window's area when the 3D view does not fill the monitor:
    /// `u = x_px / monitor_width_px`, `v = 1 − y_px / monitor_height_px`.
    pub fn sub_rect(&self, u0: f32, v0: f32, u1: f32, v1: f32) -> Result<Self, ScreenError> {
        Self::new(
            self.point_at(u0, v0),
            self.point_at(u1, v0),
            self.point_at(u0, v1),
        )
    }

    /// A point on the screen from screen units (u, v) in [0, 1]² (0, 0 = lower left).
    pub fn point_at(&self, u: f32, v: f32) -> Vec3 {
        self.lower_left_m
            + (self.lower_right_m - self.lower_left_m) * u
            + (self.upper_left_m - self.lower_left_m) * v
    }
}

fn check_size(width_m: f32, height_m: f32) -> Result<(), ScreenError> {
    let ok = |s: f32| s.is_finite() && (MIN_SCREEN_SIDE_M..=MAX_SCREEN_SIDE_M).contains(&s);
    if ok(width_m) && ok(height_m) {
        Ok(())
    } else {
        Err(ScreenError::AbsurdSize {
            width_m,
            height_m,
            min_m: MIN_SCREEN_SIDE_M,
            max_m: MAX_SCREEN_SIDE_M,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn desktop_screen_has_expected_frame() {
        let s = ScreenRect::desktop(0.53, 0.30).expect("screen");
        assert!((s.width_m() - 0.53).abs() < 1e-6);
        assert!((s.height_m() - 0.30).abs() < 1e-6);
        assert!((s.normal() - Vec3::Z).length() < 1e-6);
        assert!((s.upper_right_m() - Vec3::new(0.265, 0.15, 0.0)).length() < 1e-6);
        assert!((s.distance_in_front_m(Vec3::new(0.0, 0.0, 0.6)) - 0.6).abs() < 1e-6);
    }

    #[test]
    fn sub_rect_is_the_window_area() {
        let s = ScreenRect::desktop(0.53, 0.30).expect("screen");
        // The right half of the monitor, top 2/3.
        let w = s.sub_rect(0.5, 1.0 / 3.0, 1.0, 1.0).expect("window");
        assert!((w.width_m() - 0.265).abs() < 1e-6 && (w.height_m() - 0.2).abs() < 1e-6);
        assert!((w.upper_right_m() - s.upper_right_m()).length() < 1e-6);
        assert!((w.lower_left_m - Vec3::new(0.0, -0.05, 0.0)).length() < 1e-6);
        assert!(s.sub_rect(0.5, 0.5, 0.5, 1.0).is_err(), "zero width");
    }

    #[test]
    fn bad_rectangles_are_rejected() {
        let e = ScreenRect::new(Vec3::ZERO, Vec3::X * 0.5, Vec3::new(0.1, 0.3, 0.0));
        assert!(matches!(e, Err(ScreenError::NotRectangular { .. })));
        let e = ScreenRect::new(Vec3::ZERO, Vec3::X * 53.0, Vec3::Y * 30.0);
        assert!(matches!(e, Err(ScreenError::AbsurdSize { .. })), "{e:?}");
        let e = ScreenRect::new(Vec3::ZERO, Vec3::X * f32::NAN, Vec3::Y);
        assert!(matches!(e, Err(ScreenError::NotFinite(Corner::LowerRight))));
    }
}
