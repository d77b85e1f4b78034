//! Stereo: eye positions from a head pose, off-axis projections, output (composition) modes.
