//! Screen calibration: the screen rectangle from measured corners, tracker frames (tracker to
//! world, sensor to wand tip, head sensor to eyes) and calibration profiles (TOML files in
//! `calibration/`).

pub mod drive;
pub mod fit;
pub mod frames;
pub mod procedure;
pub mod profile;
pub mod sample_session;
pub mod screen;
pub mod sighting;

pub use fit::{FitError, FitOptions, ScreenFit, Units, fit_screen};
pub use frames::{BaselineMode, Eye, HeadEyes, TrackerFrames};
pub use procedure::{CornerProcedure, ProcedureConfig, ProcedureEvent, Step, WandInput};
pub use profile::{CalibrationProfile, ProfileError};
pub use screen::{Corner, ScreenError, ScreenRect};
