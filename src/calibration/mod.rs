//! Screen calibration: the screen rectangle from measured corners, tracker frames (tracker to
//! world, sensor to wand tip, head sensor to eyes) and calibration profiles (TOML files in
//! `calibration/`).

pub mod frames;
pub mod profile;
pub mod screen;

pub use frames::{BaselineMode, Eye, HeadEyes, TrackerFrames};
pub use profile::{CalibrationProfile, ProfileError};
pub use screen::{Corner, ScreenError, ScreenRect};
