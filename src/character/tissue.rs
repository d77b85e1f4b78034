//! The connective tissue layer: one-sided springs ("rubber bands") from skin points to anchors
//! fixed on muscle surfaces (paper eq. 3).

use glam::Vec3;

use super::shape::ShapeId;

/// A connective-tissue spring between a skin point and an anchor on a shape.
///
/// The anchor is stored in the shape's *rest* (undeformed) space, so it follows the skeleton and
/// stays on the surface as the muscle flexes: its world position is
/// [`super::shape::ShapeInstance::rest_point_to_world`]`(anchor_rest_m)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TissueSpring {
    /// Index of the skin point ([`super::skin::Skin::index`]).
    pub skin_point: u32,
    /// The shape carrying the anchor.
    pub shape: ShapeId,
    /// Anchor in the shape's rest space, metres.
    pub anchor_rest_m: Vec3,
    /// Spring constant k_s, N/m (≥ 0).
    pub stiffness_n_per_m: f32,
    /// Damping coefficient k_d, N·s/m (≥ 0).
    pub damping_n_s_per_m: f32,
    /// Rest length l⁰, metres (≥ 0): the spring is slack while shorter.
    pub rest_length_m: f32,
}

impl TissueSpring {
    /// Force on the skin point (eq. 3), newtons. `l_m` = skin point − anchor, `l_dot_m_per_s` =
    /// its rate of change (skin velocity − anchor velocity). Zero while `|l| ≤ l⁰`; beyond, the
    /// magnitude `k_s(|l| − l⁰) + k_d (l̇·l̂)` is clamped at zero so the spring only ever pulls
    /// the skin towards the anchor.
    #[inline]
    pub fn force(&self, l_m: Vec3, l_dot_m_per_s: Vec3) -> Vec3 {
        let len = l_m.length();
        if len <= self.rest_length_m || len <= 0.0 {
            return Vec3::ZERO;
        }
        let dir = l_m / len;
        let magnitude = self.stiffness_n_per_m * (len - self.rest_length_m)
            + self.damping_n_s_per_m * l_dot_m_per_s.dot(dir);
        -dir * magnitude.max(0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn springs_only_pull() {
        let s = TissueSpring {
            skin_point: 0,
            shape: ShapeId(0),
            anchor_rest_m: Vec3::ZERO,
            stiffness_n_per_m: 100.0,
            damping_n_s_per_m: 2.0,
            rest_length_m: 0.01,
        };
        // Slack: no force, whatever the velocity.
        assert_eq!(
            s.force(Vec3::new(0.005, 0.0, 0.0), Vec3::X * 10.0),
            Vec3::ZERO
        );
        // Stretched: pulls back towards the anchor with k_s·(|l|−l0).
        let f = s.force(Vec3::new(0.03, 0.0, 0.0), Vec3::ZERO);
        assert!((f - Vec3::new(-2.0, 0.0, 0.0)).length() < 1e-5);
        // Stretched but approaching fast: damping would push; clamped to zero.
        let f = s.force(Vec3::new(0.03, 0.0, 0.0), Vec3::new(-10.0, 0.0, 0.0));
        assert_eq!(f, Vec3::ZERO);
    }
}
