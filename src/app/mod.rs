//! The application: the frame loop and its scheduler, app state, the render scene, the GPU
//! edge and headless replay. The window is `leman run` (src/cmd/run.rs) over [`crate::ui`].

pub mod gpu;
pub mod replay;
pub mod scene;
pub mod scheduler;
pub mod setup;
pub mod skin_display;
pub mod state;
pub mod vehicle;
