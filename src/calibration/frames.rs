//! Tracker frames: where a tracker's base sits in the world (the "pre" transform), where the
//! wand tip and the eyes sit relative to their sensors (the "post" transforms).

use crate::pose::Pose;
use glam::Vec3;
use serde::{Deserialize, Serialize};

/// Which eye.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Eye {
    /// The left eye.
    Left,
    /// The right eye.
    Right,
    /// The midpoint between the eyes (mono, head-coupled).
    Center,
}

/// How the interocular baseline is oriented.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BaselineMode {
    /// The baseline rotates with the tracked head (normal 6-DOF trackers).
    #[default]
    FollowHead,
    /// The baseline stays parallel to the screen's right edge, whatever the head's rotation;
    /// only the eye midpoint follows the tracker (webcam trackers with poor rotation).
    ParallelToScreen,
}

/// Eyes relative to the head sensor, all in the sensor's frame: the eye midpoint offset `c`, the
/// unit interocular axis `a` (from the left eye to the right eye) and the IPD `δ`:
/// left = H(c − δ/2 a), right = H(c + δ/2 a).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HeadEyes {
    /// Eye midpoint in the head sensor's frame, metres.
    pub eye_midpoint_in_sensor_m: Vec3,
    /// Unit vector from left eye to right eye in the head sensor's frame.
    pub interocular_axis_in_sensor: Vec3,
    /// Interpupillary distance, metres.
    pub ipd_m: f32,
}

impl Default for HeadEyes {
    /// Sensor at the eye midpoint, +X to the right, IPD 0.063 m.
    fn default() -> Self {
        Self {
            eye_midpoint_in_sensor_m: Vec3::ZERO,
            interocular_axis_in_sensor: Vec3::X,
            ipd_m: 0.063,
        }
    }
}

impl HeadEyes {
    /// An eye's position in the head sensor's frame, with `ipd_m` in place of the profile's
    /// (so a comfort limit can shrink the baseline).
    pub fn eye_in_sensor_m(&self, eye: Eye, ipd_m: f32) -> Vec3 {
        let axis = self.interocular_axis_in_sensor.normalize_or_zero();
        let half = axis * (ipd_m * 0.5);
        match eye {
            Eye::Left => self.eye_midpoint_in_sensor_m - half,
            Eye::Right => self.eye_midpoint_in_sensor_m + half,
            Eye::Center => self.eye_midpoint_in_sensor_m,
        }
    }

    /// An eye's world position from the head sensor's world pose.
    ///
    /// `screen_right` is the screen's unit right vector, used only by
    /// [`BaselineMode::ParallelToScreen`]: the midpoint follows the head, the baseline lies
    /// along `screen_right`.
    pub fn eye_in_world_m(
        &self,
        eye: Eye,
        world_from_head_sensor: &Pose,
        ipd_m: f32,
        baseline: BaselineMode,
        screen_right: Vec3,
    ) -> Vec3 {
        match baseline {
            BaselineMode::FollowHead => {
                world_from_head_sensor.transform_point(self.eye_in_sensor_m(eye, ipd_m))
            }
            BaselineMode::ParallelToScreen => {
                let mid = world_from_head_sensor.transform_point(self.eye_midpoint_in_sensor_m);
                let half = screen_right.normalize_or_zero() * (ipd_m * 0.5);
                match eye {
                    Eye::Left => mid - half,
                    Eye::Right => mid + half,
                    Eye::Center => mid,
                }
            }
        }
    }
}

/// One tracker's frames: `world_from_tracker` (its base in the world, the "pre" transform) and
/// per-sensor "post" transforms.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TrackerFrames {
    /// The tracker base (transmitter) in the world frame.
    pub world_from_tracker: Pose,
    /// The wand (3D mouse) tip in the wand sensor's frame (sensor-to-tip).
    pub wand_tip_in_sensor_m: Vec3,
}

impl Default for TrackerFrames {
    fn default() -> Self {
        Self {
            world_from_tracker: Pose::IDENTITY,
            wand_tip_in_sensor_m: Vec3::ZERO,
        }
    }
}

impl TrackerFrames {
    /// A sensor's world pose from its pose in the tracker frame.
    pub fn world_from_sensor(&self, tracker_from_sensor: &Pose) -> Pose {
        self.world_from_tracker * *tracker_from_sensor
    }

    /// The wand tip in the world from the wand sensor's pose in the tracker frame.
    pub fn wand_tip_in_world_m(&self, tracker_from_wand_sensor: &Pose) -> Vec3 {
        self.world_from_sensor(tracker_from_wand_sensor)
            .transform_point(self.wand_tip_in_sensor_m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Quat;

    #[test]
    fn baseline_rotates_with_head_or_stays_parallel() {
        let eyes = HeadEyes {
            eye_midpoint_in_sensor_m: Vec3::new(0.0, -0.05, -0.08),
            interocular_axis_in_sensor: Vec3::X,
            ipd_m: 0.064,
        };
        let head = Pose::new(
            Vec3::new(0.1, 0.2, 0.6),
            Quat::from_rotation_y(std::f32::consts::FRAC_PI_2),
        );
        let l = eyes.eye_in_world_m(Eye::Left, &head, 0.064, BaselineMode::FollowHead, Vec3::X);
        let r = eyes.eye_in_world_m(Eye::Right, &head, 0.064, BaselineMode::FollowHead, Vec3::X);
        // Rotating +90° about Y maps sensor +X to world −Z.
        assert!(((r - l) - Vec3::new(0.0, 0.0, -0.064)).length() < 1e-5);
        let mid = head.transform_point(eyes.eye_midpoint_in_sensor_m);
        assert!(((l + r) * 0.5 - mid).length() < 1e-5);
        let l = eyes.eye_in_world_m(
            Eye::Left,
            &head,
            0.064,
            BaselineMode::ParallelToScreen,
            Vec3::X,
        );
        let r = eyes.eye_in_world_m(
            Eye::Right,
            &head,
            0.064,
            BaselineMode::ParallelToScreen,
            Vec3::X,
        );
        assert!(((r - l) - Vec3::new(0.064, 0.0, 0.0)).length() < 1e-5);
        assert!(((l + r) * 0.5 - mid).length() < 1e-5);
    }

    #[test]
    fn pre_and_post_transforms_compose() {
        let frames = TrackerFrames {
            world_from_tracker: Pose::new(Vec3::new(0.0, -0.3, 0.2), Quat::from_rotation_x(0.5)),
            wand_tip_in_sensor_m: Vec3::new(0.0, 0.0, -0.1),
        };
        let sensor = Pose::new(Vec3::new(0.1, 0.0, 0.3), Quat::from_rotation_z(0.3));
        let expect = frames
            .world_from_tracker
            .transform_point(sensor.transform_point(Vec3::new(0.0, 0.0, -0.1)));
        assert!((frames.wand_tip_in_world_m(&sensor) - expect).length() < 1e-6);
    }
}
