//! Stereo: eye positions from a head pose, Kooima's off-axis projection per eye (wgpu [0, 1]
//! depth), and the output modes as a composition recipe (pure data) that the renderer executes.
//!
//! Typical use, each frame:
//! ```
//! use leman::calibration::CalibrationProfile;
//! use leman::pose::Pose;
//! use leman::stereo::{compose, eye_views, OutputSettings, StereoMode, ViewSettings};
//! let profile = CalibrationProfile::default();
//! let head = Pose::from_translation(glam::Vec3::new(0.0, 0.0, 0.6));
//! let views = eye_views(&profile, &head, &ViewSettings::default()).expect("finite pose");
//! let settings = OutputSettings { mode: StereoMode::AnaglyphRedCyan, ..OutputSettings::default() };
//! let recipe = compose(&views, &settings, [1280, 720]);
//! for pass in recipe.passes_for_frame(0) {
//!     // render pass.view.clip_from_world into pass.viewport of pass.target ...
//!     assert!(pass.view.clip_from_world.is_finite());
//! }
//! ```

pub mod composition;
pub mod view;

pub use crate::calibration::frames::{BaselineMode, Eye};
pub use composition::{
    ColorMask, Composition, EyePass, OutputSettings, Parity, StereoMode, ViewportPx, compose,
};
pub use view::{
    ComfortLimits, EyeView, Frustum, StereoError, StereoViews, ViewSettings, eye_views,
    eye_views_for, off_axis_view,
};
