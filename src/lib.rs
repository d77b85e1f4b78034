//! `leman`: a head-tracked stereo workstation for building and animating layered, elastically
//! deformable characters.
//!
//! The library is a pure core (devices' protocol decoders, calibration, stereo math, the
//! character model, both simulations, the frame scheduler) with I/O at the edges (transports,
//! the window, the GPU, files). See `DESIGN.md` in the shared folder and README.md for the map.

pub mod anim;
pub mod app;
pub mod calibration;
pub mod character;
pub mod clock;
pub mod decimal;
pub mod devices;
pub mod files;
pub mod pose;
#[cfg(test)]
mod proptest_cases;
pub mod render;
pub mod sim;
pub mod stereo;
#[cfg(test)]
mod test_noise;
pub mod tracking;
pub mod ui;
