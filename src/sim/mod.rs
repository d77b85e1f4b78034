//! Simulation: the deformation models behind one interface, and the integrators they share.

pub mod ode;
pub mod surface;
