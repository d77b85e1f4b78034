//! Eye views: eye positions from the tracked head and Kooima's generalized (off-axis)
//! perspective projection per eye, with wgpu's [0, 1] clip depth.
//!
//! For screen corners `pa` (lower left), `pb` (lower right), `pc` (upper left) and an eye `pe`:
//! `vr`, `vu`, `vn` are the screen's right, up and normal (toward the viewer) unit vectors;
//! `d = −vn·(pa − pe)` is the eye's distance to the screen plane; the frustum's extents at the
//! near plane are `l = vr·(pa−pe) n/d`, `r = vr·(pb−pe) n/d`, `b = vu·(pa−pe) n/d`,
//! `t = vu·(pc−pe) n/d`; and `clip_from_world = frustum(l, r, b, t, n, f) · [rows vr, vu, vn] ·
//! translate(−pe)`. View space is therefore aligned with the screen (x right, y up, looking
//! down −z), not with the head: the screen is a fixed window into the world.

use crate::calibration::frames::{BaselineMode, Eye, HeadEyes};
use crate::calibration::profile::CalibrationProfile;
use crate::calibration::screen::ScreenRect;
use crate::pose::Pose;
use glam::{Mat4, Vec3, Vec4};
use serde::{Deserialize, Serialize};

/// Why eye views could not be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StereoError {
    /// The head pose or an eye position is NaN or infinite.
    #[error("head pose is not finite")]
    NotFinite,
    /// Near and far planes are not 0 < near < far (finite).
    #[error("bad clip planes: near {near_m} m, far {far_m} m (need 0 < near < far)")]
    BadClipPlanes {
        /// Near plane distance.
        near_m: f32,
        /// Far plane distance.
        far_m: f32,
    },
    /// The eye is on or behind the screen plane (only from [`off_axis_view`]; [`eye_views`]
    /// clamps instead).
    #[error("eye is {distance_m:.4} m in front of the screen plane (must be in front)")]
    EyeNotInFront {
        /// Signed distance in front of the screen.
        distance_m: f32,
    },
}

/// The frustum's extents on the near plane, in the screen-aligned view frame (metres).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Frustum {
    /// Left extent at the near plane.
    pub left_m: f32,
    /// Right extent at the near plane.
    pub right_m: f32,
    /// Bottom extent at the near plane.
    pub bottom_m: f32,
    /// Top extent at the near plane.
    pub top_m: f32,
    /// Near plane distance.
    pub near_m: f32,
    /// Far plane distance.
    pub far_m: f32,
}

/// Everything a renderer needs to draw one eye.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EyeView {
    /// Which eye this is (after any swap it is still the physical eye it was computed for).
    pub eye: Eye,
    /// Eye position in the world frame, metres.
    pub position_m: Vec3,
    /// World to the screen-aligned eye frame (x right, y up along the screen, −z into it).
    pub view_from_world: Mat4,
    /// The off-axis projection, wgpu convention (NDC z in [0, 1], y up).
    pub clip_from_view: Mat4,
    /// `clip_from_view · view_from_world`.
    pub clip_from_world: Mat4,
    /// Frustum extents on the near plane.
    pub frustum: Frustum,
    /// Near plane distance, metres.
    pub near_m: f32,
    /// Far plane distance, metres.
    pub far_m: f32,
    /// Distance from the eye to the screen plane, metres.
    pub screen_distance_m: f32,
}

impl EyeView {
    /// Projects a world point to normalised device coordinates (x, y in [−1, 1] on screen,
    /// z in [0, 1] between near and far). `None` when the point is at the eye's plane.
    pub fn ndc(&self, p_world: Vec3) -> Option<Vec3> {
        let c = self.clip_from_world * Vec4::new(p_world.x, p_world.y, p_world.z, 1.0);
        if c.w.abs() < 1e-12 {
            None
        } else {
            Some(c.truncate() / c.w)
        }
    }
}

/// Kooima's off-axis view for one eye. The eye must be strictly in front of the screen plane.
pub fn off_axis_view(
    screen: &ScreenRect,
    eye: Eye,
    eye_world_m: Vec3,
    near_m: f32,
    far_m: f32,
) -> Result<EyeView, StereoError> {
    if !eye_world_m.is_finite() {
        return Err(StereoError::NotFinite);
    }
    if !(near_m.is_finite() && far_m.is_finite() && near_m > 0.0 && far_m > near_m) {
        return Err(StereoError::BadClipPlanes { near_m, far_m });
    }
    let (vr, vu, vn) = (screen.right(), screen.up(), screen.normal());
    let va = screen.lower_left_m - eye_world_m;
    let vb = screen.lower_right_m - eye_world_m;
    let vc = screen.upper_left_m - eye_world_m;
    let d = -vn.dot(va);
    if d.is_nan() || d <= 1e-6 {
        return Err(StereoError::EyeNotInFront { distance_m: d });
    }
    let k = near_m / d;
    let frustum = Frustum {
        left_m: vr.dot(va) * k,
        right_m: vr.dot(vb) * k,
        bottom_m: vu.dot(va) * k,
        top_m: vu.dot(vc) * k,
        near_m,
        far_m,
    };
    let clip_from_view = glam::camera::rh::proj::directx::frustum(
        frustum.left_m,
        frustum.right_m,
        frustum.bottom_m,
        frustum.top_m,
        near_m,
        far_m,
    );
    // Rows vr, vu, vn: the transpose of the matrix whose columns they are.
    let rotation = Mat4::from_mat3(screen.world_from_screen_rotation().transpose());
    let view_from_world = rotation * Mat4::from_translation(-eye_world_m);
    let clip_from_world = clip_from_view * view_from_world;
    if !(clip_from_world.is_finite() && view_from_world.is_finite()) {
        return Err(StereoError::NotFinite);
    }
    Ok(EyeView {
        eye,
        position_m: eye_world_m,
        view_from_world,
        clip_from_view,
        clip_from_world,
        frustum,
        near_m,
        far_m,
        screen_distance_m: d,
    })
}

/// Limits on screen parallax for comfort. Parallax of a point at distance `z` from the eyes
/// (along the screen normal) with the screen at distance `d` is `ipd·(z − d)/z` on the screen;
/// when a limit would be exceeded for the given content depth range, the baseline is shrunk
/// (the IPD used for rendering is reduced) until it is met. `None` = physically correct.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct ComfortLimits {
    /// Largest uncrossed (behind the screen) parallax on the screen, metres.
    pub max_uncrossed_parallax_m: Option<f32>,
    /// Largest crossed (in front of the screen) parallax on the screen, metres.
    pub max_crossed_parallax_m: Option<f32>,
    /// How far content reaches in front of the screen (toward the viewer), metres.
    pub content_in_front_m: f32,
    /// How far content reaches behind the screen, metres.
    pub content_behind_m: f32,
}

impl ComfortLimits {
    /// The IPD to render with: `ipd_m`, reduced if a limit would be exceeded for an eye midpoint
    /// `screen_distance_m` from the screen.
    pub fn limited_ipd_m(&self, ipd_m: f32, screen_distance_m: f32) -> f32 {
        let d = screen_distance_m;
        let mut ipd = ipd_m;
        if let Some(max) = self.max_uncrossed_parallax_m {
            let z = d + self.content_behind_m.max(0.0);
            if z > d && z.is_finite() {
                // ipd (z − d) / z <= max
                ipd = ipd.min(max.max(0.0) * z / (z - d));
            }
        }
        if let Some(max) = self.max_crossed_parallax_m {
            let z = d - self.content_in_front_m.max(0.0);
            if z < d && z > 1e-3 {
                // ipd (d − z) / z <= max
                ipd = ipd.min(max.max(0.0) * z / (d - z));
            }
        }
        if ipd.is_finite() { ipd.max(0.0) } else { ipd_m }
    }
}

/// Settings for turning a head pose into eye views.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ViewSettings {
    /// Near clip plane distance from the eye, metres.
    pub near_m: f32,
    /// Far clip plane distance from the eye, metres.
    pub far_m: f32,
    /// Use this IPD instead of the profile's (e.g. from the UI), metres.
    pub ipd_override_m: Option<f32>,
    /// Orientation of the eye baseline; `None` = the profile's.
    pub baseline_override: Option<BaselineMode>,
    /// Parallax limits for comfort.
    pub comfort: ComfortLimits,
    /// Eyes closer than this to the screen plane (or behind it) are moved out to it along the
    /// normal, so the projection stays valid; [`StereoViews::clamped`] says when it happened.
    pub min_eye_distance_m: f32,
}

impl Default for ViewSettings {
    fn default() -> Self {
        Self {
            near_m: 0.01,
            far_m: 100.0,
            ipd_override_m: None,
            baseline_override: None,
            comfort: ComfortLimits::default(),
            min_eye_distance_m: 0.05,
        }
    }
}

/// Both eyes' views and the midpoint's (for mono, head-coupled).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StereoViews {
    /// The left eye.
    pub left: EyeView,
    /// The right eye.
    pub right: EyeView,
    /// The eye midpoint (mono).
    pub center: EyeView,
    /// The IPD actually used (after override and comfort limits), metres.
    pub ipd_used_m: f32,
    /// True when an eye was too close to (or behind) the screen and was moved out.
    pub clamped: bool,
}

impl StereoViews {
    /// One eye's view.
    pub fn get(&self, eye: Eye) -> &EyeView {
        match eye {
            Eye::Left => &self.left,
            Eye::Right => &self.right,
            Eye::Center => &self.center,
        }
    }
}

/// Both eyes' views from a screen, the head-to-eyes offsets and the head sensor's world pose.
/// An eye closer than `settings.min_eye_distance_m` to the screen plane is moved out along the
/// normal (so a head behind the screen still gives finite matrices); a non-finite pose or bad
/// clip planes are errors (keep the last good views).
pub fn eye_views_for(
    screen: &ScreenRect,
    head_eyes: &HeadEyes,
    default_baseline: BaselineMode,
    world_from_head_sensor: &Pose,
    settings: &ViewSettings,
) -> Result<StereoViews, StereoError> {
    if !(world_from_head_sensor.position_m.is_finite()
        && world_from_head_sensor.orientation.is_finite())
    {
        return Err(StereoError::NotFinite);
    }
    let head = Pose::new(
        world_from_head_sensor.position_m,
        world_from_head_sensor.orientation.normalize(),
    );
    let baseline = settings.baseline_override.unwrap_or(default_baseline);
    let ipd_m = settings.ipd_override_m.unwrap_or(head_eyes.ipd_m);
    if !ipd_m.is_finite() {
        return Err(StereoError::NotFinite);
    }
    let right = screen.right();
    let mid = head_eyes.eye_in_world_m(Eye::Center, &head, ipd_m, baseline, right);
    let ipd_used_m = settings
        .comfort
        .limited_ipd_m(ipd_m.max(0.0), screen.distance_in_front_m(mid));
    let mut clamped = false;
    let mut view = |eye: Eye| {
        let mut p = head_eyes.eye_in_world_m(eye, &head, ipd_used_m, baseline, right);
        let d = screen.distance_in_front_m(p);
        let min_d = settings.min_eye_distance_m.max(1e-4);
        if d.is_nan() || d < min_d {
            p += screen.normal() * (min_d - d);
            clamped = true;
        }
        off_axis_view(screen, eye, p, settings.near_m, settings.far_m)
    };
    let left = view(Eye::Left)?;
    let right = view(Eye::Right)?;
    let center = view(Eye::Center)?;
    Ok(StereoViews {
        left,
        right,
        center,
        ipd_used_m,
        clamped,
    })
}

/// Both eyes' views from a calibration profile and the head sensor's pose in the world frame.
pub fn eye_views(
    profile: &CalibrationProfile,
    world_from_head_sensor: &Pose,
    settings: &ViewSettings,
) -> Result<StereoViews, StereoError> {
    eye_views_for(
        &profile.screen,
        &profile.head_eyes,
        profile.baseline,
        world_from_head_sensor,
        settings,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Quat;
    use proptest::prelude::*;

    fn desktop() -> ScreenRect {
        ScreenRect::desktop(0.53, 0.30).expect("screen")
    }

    fn tilted() -> ScreenRect {
        ScreenRect::from_center(
            Vec3::new(0.2, 1.1, -0.4),
            Vec3::new(0.9, 0.0, 0.3),
            Vec3::new(0.1, 0.95, 0.25),
            0.6,
            0.34,
        )
        .expect("screen")
    }

    fn check_corners(screen: &ScreenRect, eye: Vec3, near: f32, far: f32) {
        let v = off_axis_view(screen, Eye::Left, eye, near, far).expect("view");
        let d = v.screen_distance_m;
        let depth_at_screen = far / (far - near) * (1.0 - near / d);
        for (corner, nx, ny) in [
            (screen.lower_left_m, -1.0, -1.0),
            (screen.lower_right_m, 1.0, -1.0),
            (screen.upper_left_m, -1.0, 1.0),
            (screen.upper_right_m(), 1.0, 1.0),
        ] {
            let ndc = v.ndc(corner).expect("ndc");
            assert!((ndc.x - nx).abs() < 1e-3, "{ndc} for eye {eye}");
            assert!((ndc.y - ny).abs() < 1e-3, "{ndc} for eye {eye}");
            assert!(
                (ndc.z - depth_at_screen).abs() < 1e-3,
                "{ndc} vs {depth_at_screen}"
            );
            assert!((0.0..=1.0).contains(&ndc.z));
        }
    }

    proptest! {
        #[test]
        fn screen_corners_land_on_ndc_corners_for_any_eye_in_front(
            u in -1.0f32..2.0, v in -1.0f32..2.0, dist in 0.1f32..3.0, tilted_screen: bool,
            near in 0.005f32..0.09, far in 5.0f32..500.0,
        ) {
            let s = if tilted_screen { tilted() } else { desktop() };
            let eye = s.point_at(u, v) + s.normal() * dist;
            check_corners(&s, eye, near, far);
        }

        #[test]
        fn points_on_a_ray_through_the_eye_share_ndc_xy(
            u in -0.5f32..1.5, v in -0.5f32..1.5, dist in 0.2f32..2.0,
            su in 0.0f32..1.0, sv in 0.0f32..1.0, t1 in 0.1f32..0.9, t2 in 1.1f32..5.0,
        ) {
            let s = tilted();
            let eye = s.point_at(u, v) + s.normal() * dist;
            let view = off_axis_view(&s, Eye::Right, eye, 0.01, 100.0).expect("view");
            let target = s.point_at(su, sv);
            let a = view.ndc(eye + (target - eye) * t1).expect("a");
            let b = view.ndc(eye + (target - eye) * t2).expect("b");
            let c = view.ndc(target).expect("c");
            prop_assert!((a.truncate() - b.truncate()).length() < 1e-3);
            prop_assert!((a.truncate() - c.truncate()).length() < 1e-3);
            prop_assert!(a.z < c.z && c.z < b.z, "depth increases away from the eye");
        }
    }

    #[test]
    fn centred_eye_gives_symmetric_frustum() {
        let s = desktop();
        let v = off_axis_view(&s, Eye::Center, Vec3::new(0.0, 0.0, 0.6), 0.01, 10.0).expect("v");
        let f = v.frustum;
        assert!((f.left_m + f.right_m).abs() < 1e-7, "{f:?}");
        assert!((f.bottom_m + f.top_m).abs() < 1e-7, "{f:?}");
        // 0.265 m at 0.6 m, scaled to the near plane.
        assert!((f.right_m - 0.265 * 0.01 / 0.6).abs() < 1e-7);
        // A symmetric frustum equals glam's symmetric perspective.
        let fov_y = 2.0 * (0.15f32 / 0.6).atan();
        let p = glam::camera::rh::proj::directx::perspective(fov_y, 0.53 / 0.30, 0.01, 10.0);
        assert!(
            v.clip_from_view.abs_diff_eq(p, 1e-4),
            "{:?} vs {p:?}",
            v.clip_from_view
        );
        // Near maps to depth 0, far to depth 1.
        let near = v.ndc(Vec3::new(0.0, 0.0, 0.59)).expect("near");
        let far = v.ndc(Vec3::new(0.0, 0.0, -9.4)).expect("far");
        assert!(near.z.abs() < 1e-4 && (far.z - 1.0).abs() < 1e-4);
    }

    #[test]
    fn swapping_eyes_mirrors_the_frusta() {
        let profile = CalibrationProfile::default();
        let head = Pose::from_translation(Vec3::new(0.0, 0.05, 0.6));
        let views = eye_views(&profile, &head, &ViewSettings::default()).expect("views");
        let (l, r) = (views.left.frustum, views.right.frustum);
        assert!((l.left_m + r.right_m).abs() < 1e-6 && (l.right_m + r.left_m).abs() < 1e-6);
        assert!((l.top_m - r.top_m).abs() < 1e-7 && (l.bottom_m - r.bottom_m).abs() < 1e-7);
        // Mirroring the world in x maps the left eye's projection of a point onto the right
        // eye's projection of the mirrored point.
        let p = Vec3::new(0.07, -0.03, -0.2);
        let a = views.left.ndc(p).expect("a");
        let b = views.right.ndc(Vec3::new(-p.x, p.y, p.z)).expect("b");
        assert!((a.x + b.x).abs() < 1e-5 && (a.y - b.y).abs() < 1e-5 && (a.z - b.z).abs() < 1e-6);
        assert!((views.right.position_m - views.left.position_m - Vec3::X * 0.063).length() < 1e-6);
    }

    #[test]
    fn head_rotation_turns_the_baseline_unless_parallel_mode() {
        let profile = CalibrationProfile::default();
        let head = Pose::new(Vec3::new(0.0, 0.0, 0.6), Quat::from_rotation_y(0.5));
        let v = eye_views(&profile, &head, &ViewSettings::default()).expect("views");
        let b = v.right.position_m - v.left.position_m;
        assert!(b.z.abs() > 0.02);
        let settings = ViewSettings {
            baseline_override: Some(BaselineMode::ParallelToScreen),
            ..ViewSettings::default()
        };
        let v = eye_views(&profile, &head, &settings).expect("views");
        let b = v.right.position_m - v.left.position_m;
        assert!((b - Vec3::X * 0.063).length() < 1e-6);
    }

    #[test]
    fn eye_behind_screen_is_clamped_and_bad_input_is_an_error() {
        let profile = CalibrationProfile::default();
        let head = Pose::from_translation(Vec3::new(0.0, 0.0, -0.2));
        let v = eye_views(&profile, &head, &ViewSettings::default()).expect("views");
        assert!(v.clamped);
        assert!(v.left.clip_from_world.is_finite());
        assert!((v.left.screen_distance_m - 0.05).abs() < 1e-5);
        let bad = Pose::from_translation(Vec3::new(f32::NAN, 0.0, 0.5));
        assert_eq!(
            eye_views(&profile, &bad, &ViewSettings::default()),
            Err(StereoError::NotFinite)
        );
        let s = ViewSettings {
            near_m: 1.0,
            far_m: 0.5,
            ..ViewSettings::default()
        };
        let head = Pose::from_translation(Vec3::new(0.0, 0.0, 0.6));
        assert!(matches!(
            eye_views(&profile, &head, &s),
            Err(StereoError::BadClipPlanes { .. })
        ));
        assert!(matches!(
            off_axis_view(&desktop(), Eye::Left, Vec3::new(0.0, 0.0, -0.1), 0.01, 10.0),
            Err(StereoError::EyeNotInFront { .. })
        ));
    }

    #[test]
    fn comfort_limits_shrink_the_baseline() {
        let profile = CalibrationProfile::default();
        let head = Pose::from_translation(Vec3::new(0.0, 0.0, 0.6));
        let settings = ViewSettings {
            comfort: ComfortLimits {
                max_uncrossed_parallax_m: Some(0.02),
                max_crossed_parallax_m: Some(0.02),
                content_in_front_m: 0.3,
                content_behind_m: 0.6,
            },
            ..ViewSettings::default()
        };
        let v = eye_views(&profile, &head, &settings).expect("views");
        // Uncrossed: ipd·(1.2−0.6)/1.2 <= 0.02 -> ipd <= 0.04; crossed: ipd·0.3/0.3 <= 0.02.
        assert!((v.ipd_used_m - 0.02).abs() < 1e-6, "{}", v.ipd_used_m);
        let baseline = (v.right.position_m - v.left.position_m).length();
        assert!((baseline - 0.02).abs() < 1e-6);
        let none = eye_views(&profile, &head, &ViewSettings::default()).expect("views");
        assert!((none.ipd_used_m - 0.063).abs() < 1e-7);
    }
}
