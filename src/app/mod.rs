//! The application: the frame loop and its scheduler, app state and undoable edit commands.

pub mod scene;
pub mod scheduler;
pub mod vehicle;
