//! Integrators and step-size control shared by both deformation models.
