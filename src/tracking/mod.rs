//! Tracking: pose filtering (One Euro, per role, or raw) and prediction of the head pose to the
//! expected display time. Pure: samples and their timestamps in, poses out.

pub mod one_euro;
pub mod predict;
pub mod role;

pub use one_euro::{FilterConfig, PoseFilter};
pub use predict::{PosePredictor, PredictorConfig};
pub use role::RoleTracker;
