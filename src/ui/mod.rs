//! egui panels of the workstation.
