//! Rigid poses (position + orientation), the currency between trackers, calibration, stereo and
//! tools. Names follow `target_from_source`: `world_from_head * p_head` gives `p_world`.

use glam::{Mat4, Quat, Vec3};
use serde::{Deserialize, Serialize};

/// A rigid transform: rotate by `orientation`, then translate by `position_m`.
/// Metres and a unit quaternion; the frames it maps between are named by the variable holding it.
#[derive(Clone, Copy, PartialEq, Serialize, Deserialize)]
#[repr(C)]
pub struct Pose {
    /// Translation in metres.
    pub position_m: Vec3,
    /// Always 0.0: the four bytes after `position_m`, which would otherwise be padding. glam
    /// widens a `Vec3` to four SIMD lanes for a rotation, and where that fourth lane's result
    /// is unused the compiler loads it straight from memory, here from this slot. Padding holds
    /// whatever bytes were there before, often a small integer or half a pointer, which read as
    /// a subnormal float; a multiply with a subnormal lane takes a microcode assist on this
    /// machine's AMD cores. That was 7 % of the torso's run time in `Shape::instance` alone
    /// (session 27, perf), gone with flush-to-zero or with this zero.
    #[serde(skip)]
    zero_lane: f32,
    /// Rotation (unit quaternion).
    pub orientation: Quat,
}

impl std::fmt::Debug for Pose {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Pose")
            .field("position_m", &self.position_m)
            .field("orientation", &self.orientation)
            .finish()
    }
}

impl Default for Pose {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Pose {
    /// The identity transform.
    pub const IDENTITY: Self = Self::new(Vec3::ZERO, Quat::IDENTITY);

    /// A pose from a translation (metres) and a rotation.
    pub const fn new(position_m: Vec3, orientation: Quat) -> Self {
        Self {
            position_m,
            zero_lane: 0.0,
            orientation,
        }
    }

    /// A pure translation (metres).
    pub fn from_translation(position_m: Vec3) -> Self {
        Self::new(position_m, Quat::IDENTITY)
    }

    /// Maps a point from the source frame into the target frame.
    pub fn transform_point(&self, p: Vec3) -> Vec3 {
        self.orientation * p + self.position_m
    }

    /// Maps a direction (no translation) from the source frame into the target frame.
    pub fn transform_vector(&self, v: Vec3) -> Vec3 {
        self.orientation * v
    }

    /// The inverse transform (target back to source).
    pub fn inverse(&self) -> Self {
        let inv = self.orientation.conjugate();
        Self::new(-(inv * self.position_m), inv)
    }

    /// Composition: `(a * b).transform_point(p) == a.transform_point(b.transform_point(p))`.
    pub fn mul_pose(&self, rhs: &Pose) -> Pose {
        Pose::new(
            self.transform_point(rhs.position_m),
            (self.orientation * rhs.orientation).normalize(),
        )
    }

    /// The 4×4 homogeneous matrix of this transform.
    pub fn to_mat4(&self) -> Mat4 {
        Mat4::from_rotation_translation(self.orientation, self.position_m)
    }

    /// True when every component is finite and the quaternion is (nearly) unit length.
    pub fn is_valid(&self) -> bool {
        self.position_m.is_finite()
            && self.orientation.is_finite()
            && (self.orientation.length() - 1.0).abs() < 1e-3
    }
}

impl std::ops::Mul for Pose {
    type Output = Pose;
    fn mul(self, rhs: Pose) -> Pose {
        self.mul_pose(&rhs)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_zero_lane_is_neither_written_nor_shown_and_fills_the_padding() {
        let p = Pose::new(Vec3::new(1.0, 2.0, 3.0), Quat::from_rotation_z(0.5));
        // No padding left for stale bytes: 12 bytes of position, the zero lane, 16 of rotation.
        assert_eq!(std::mem::size_of::<Pose>(), 32);
        assert_eq!(std::mem::offset_of!(Pose, zero_lane), 12);
        let json = serde_json::to_string(&p).expect("a pose serialises");
        assert!(!json.contains("zero_lane"), "{json}");
        let back: Pose = serde_json::from_str(&json).expect("its JSON reads back");
        assert_eq!(back, p);
        assert_eq!(back.zero_lane.to_bits(), 0);
        assert!(!format!("{p:?}").contains("zero_lane"));
    }

    #[test]
    fn inverse_and_composition_round_trip() {
        let a = Pose::new(Vec3::new(1.0, 2.0, 3.0), Quat::from_rotation_y(0.7));
        let b = Pose::new(Vec3::new(-0.5, 0.1, 0.0), Quat::from_rotation_x(-0.3));
        let p = Vec3::new(0.3, -0.2, 0.9);
        let ab = a * b;
        assert!((ab.transform_point(p) - a.transform_point(b.transform_point(p))).length() < 1e-5);
        assert!(((a * a.inverse()).transform_point(p) - p).length() < 1e-5);
        assert!((a.to_mat4().transform_point3(p) - a.transform_point(p)).length() < 1e-5);
    }
}
