//! Rendering with wgpu: scene drawing, stereo passes executing a composition, offscreen capture.
//!
//! Layers: [`scene`] is the plain data the app fills each frame; [`batch`] turns it into flat,
//! finite vertex arrays (pure, no GPU); [`renderer`] uploads them and draws one
//! [`renderer::DrawPass`] per eye of the stereo module's composition recipe with the stereo module's matrices; [`capture`] reads images
//! back and writes PNGs; [`device_caps`] is the one place that picks the adapter and backend.
//! The renderer reaches into no simulation model and does no projection math.

pub mod adapter;
pub mod batch;
pub mod capture;
pub mod device_caps;
pub mod egui_view;
pub mod mesh;
pub mod reference;
pub mod renderer;
pub mod scene;
pub mod subdivide;

pub use capture::RgbaImage;
pub use device_caps::{AdapterPreference, DeviceError, GpuContext};
pub use renderer::{
    ColorMask, DrawPass, FrameReport, Parity, RenderError, RenderTarget, Renderer, RendererOptions,
    ViewportPx,
};
pub use scene::{Layers, Rgba, Scene};
