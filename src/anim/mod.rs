//! Animation: key postures, splines, timelines, IK and baking (skeleton motions independent of
//! the deformation model).
//!
//! A [`keyed::Motion`] is a named list of key postures interpolated with Kochanek-Bartels
//! splines (LEMAN section 6.4); it knows only the skeleton, never the skin or the simulation.

pub mod keyed;

pub use keyed::{Extrapolation, KeyPosture, Motion};
