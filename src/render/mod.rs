//! Rendering with wgpu: scene drawing, stereo passes executing a composition, offscreen capture.
