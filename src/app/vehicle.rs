//! The navigation vehicle (LEMAN section 5.1): the Spaceball (or the keyboard standing in for
//! it) flies a virtual vehicle incrementally; the tracked head and hand are interpreted in the
//! vehicle's frame, which is the physical frame of the calibrated screen.
//!
//! `world_from_vehicle` maps points of the physical (screen) frame into the character's world.
//! Axes are velocities in the vehicle frame: translation x right, y up, z toward the user; the
//! rotation about those axes (right-hand rule).

use crate::pose::Pose;
use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};

/// Speeds at full deflection of the navigation axes.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct VehicleSpeeds {
    /// Translation speed at axis value 1, m/s.
    pub translation_m_per_s: f32,
    /// Rotation speed at axis value 1, rad/s.
    pub rotation_rad_per_s: f32,
}

impl Default for VehicleSpeeds {
    fn default() -> Self {
        Self {
            translation_m_per_s: 0.3,
            rotation_rad_per_s: 0.8,
        }
    }
}

/// The vehicle: where the physical screen frame sits in the world.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Vehicle {
    /// Physical (screen) frame to world.
    pub world_from_vehicle: Pose,
    /// Speeds at full deflection.
    pub speeds: VehicleSpeeds,
}

impl Vehicle {
    /// A vehicle at `world_from_vehicle`.
    pub fn new(world_from_vehicle: Pose) -> Self {
        Self {
            world_from_vehicle,
            speeds: VehicleSpeeds::default(),
        }
    }

    /// A vehicle that shows a box of `centre_world` and `size_m` whole through a screen of
    /// `screen_size_m` (width, height), seen from `viewer_distance_m`: the box's centre lands on the screen's
    /// axis, behind the screen as far as needed for its height to fit (with a margin).
    pub fn framing(
        centre_world: Vec3,
        size_m: Vec3,
        screen_centre_m: Vec3,
        screen_size_m: [f32; 2],
        viewer_distance_m: f32,
    ) -> Self {
        let [screen_width_m, screen_height_m] = screen_size_m;
        let aspect = if screen_width_m > 0.0 {
            screen_height_m / screen_width_m
        } else {
            1.0
        };
        let tall = size_m.y.max(size_m.x * aspect);
        let needed = 1.2 * tall.max(1e-3);
        let depth_m = if screen_height_m > 0.0 && viewer_distance_m > 0.0 {
            (viewer_distance_m * (needed / screen_height_m - 1.0)).max(-0.05)
        } else {
            0.0
        };
        // Physical point (screen centre, depth_m behind it) shows the box centre.
        let physical_target = screen_centre_m - Vec3::Z * (depth_m + 0.5 * size_m.z.max(0.0));
        let world_from_vehicle = Pose::from_translation(centre_world - physical_target);
        let pose = if world_from_vehicle.is_valid() {
            world_from_vehicle
        } else {
            Pose::IDENTITY
        };
        Self::new(pose)
    }

    /// World to physical (screen) frame.
    pub fn vehicle_from_world(&self) -> Pose {
        self.world_from_vehicle.inverse()
    }

    /// Flies the vehicle for `dt_s` seconds with navigation axes `axes` (each about [-1, 1];
    /// non-finite values and steps are ignored).
    pub fn fly(&mut self, axes: [f32; 6], dt_s: f32) {
        if !(dt_s.is_finite() && dt_s > 0.0) || axes.iter().any(|a| !a.is_finite()) {
            return;
        }
        let clamp = |a: f32| a.clamp(-1.0, 1.0);
        let v = Vec3::new(clamp(axes[0]), clamp(axes[1]), clamp(axes[2]))
            * self.speeds.translation_m_per_s;
        let w = Vec3::new(clamp(axes[3]), clamp(axes[4]), clamp(axes[5]))
            * self.speeds.rotation_rad_per_s;
        let rotation = Quat::from_scaled_axis(w * dt_s);
        let delta = Pose::new(v * dt_s, rotation);
        let next = self.world_from_vehicle * delta;
        if next.is_valid() {
            self.world_from_vehicle = next;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flying_forward_moves_the_world_towards_the_viewer() {
        let mut v = Vehicle::new(Pose::IDENTITY);
        let p_world = Vec3::new(0.0, 0.0, -1.0);
        let before = v.vehicle_from_world().transform_point(p_world);
        // W key: z = -1 (forward, into the screen).
        for _ in 0..10 {
            v.fly([0.0, 0.0, -1.0, 0.0, 0.0, 0.0], 0.1);
        }
        let after = v.vehicle_from_world().transform_point(p_world);
        assert!(
            (after.z - before.z - 0.3).abs() < 1e-5,
            "{before} -> {after}"
        );
    }

    #[test]
    fn yaw_turns_about_the_vertical_and_bad_input_is_ignored() {
        let mut v = Vehicle::new(Pose::IDENTITY);
        v.fly([0.0, 0.0, 0.0, 0.0, 1.0, 0.0], 1.0);
        let angle = v.world_from_vehicle.orientation.to_axis_angle();
        assert!((angle.1 - 0.8).abs() < 1e-5);
        assert!((angle.0 - Vec3::Y).length() < 1e-5);
        let before = v;
        v.fly([f32::NAN, 0.0, 0.0, 0.0, 0.0, 0.0], 1.0);
        v.fly([1.0, 0.0, 0.0, 0.0, 0.0, 0.0], f32::INFINITY);
        assert_eq!(v, before);
    }

    #[test]
    fn framing_puts_a_tall_box_behind_the_screen_so_it_fits() {
        let v = Vehicle::framing(
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.4, 0.8, 0.3),
            Vec3::ZERO,
            [0.53, 0.3],
            0.6,
        );
        let centre_physical = v
            .vehicle_from_world()
            .transform_point(Vec3::new(0.0, 1.0, 0.0));
        assert!(centre_physical.x.abs() < 1e-5 && centre_physical.y.abs() < 1e-5);
        // Visible height at that depth from 0.6 m: 0.3 * (0.6 + d) / 0.6 must cover 0.8.
        let d = -centre_physical.z - 0.15;
        assert!(0.3 * (0.6 + d) / 0.6 >= 0.8, "depth {d}");
    }
}
