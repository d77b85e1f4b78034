//! The GPU edge of the frame loop: a [`FrameRenderer`] that executes the stereo composition
//! with the [`Renderer`] into an offscreen target of the display's size, waits for the GPU (so
//! the measured render time is the real one, which the scheduler reserves next frame), and can
//! read the image back (headless replay frames, screenshots). The window shows the same
//! target as an egui texture.

use crate::app::state::FrameRenderer;
use crate::render::scene::Scene;
use crate::render::{RenderTarget, Renderer, RendererOptions, RgbaImage};
use crate::stereo::{OutputSettings, StereoViews, compose};

/// Renders frames into an offscreen target.
#[derive(Debug)]
pub struct OffscreenStereo {
    renderer: Renderer,
    target: Option<RenderTarget>,
    display_size_px: [u32; 2],
    /// Read every frame back into [`Self::last_image`].
    pub capture: bool,
    /// The last frame read back (when `capture` is on).
    pub last_image: Option<RgbaImage>,
    target_generation: u64,
}

impl OffscreenStereo {
    /// A renderer on `device`/`queue` drawing `display_size_px` (width, height) frames.
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        display_size_px: [u32; 2],
    ) -> Result<Self, crate::render::RenderError> {
        Ok(Self {
            renderer: Renderer::new(device, queue, RendererOptions::default())?,
            target: None,
            display_size_px,
            capture: false,
            last_image: None,
            target_generation: 0,
        })
    }

    /// Changes the display size (the target is remade at the next frame).
    pub fn set_display_size(&mut self, display_size_px: [u32; 2]) {
        self.display_size_px = [display_size_px[0].max(1), display_size_px[1].max(1)];
    }

    /// Largest output image width and height the device allows, pixels (an output of a
    /// stereo mode, [`crate::stereo::StereoMode::output_size_px`], must fit).
    pub fn max_output_px(&self) -> u32 {
        self.renderer.max_target_px()
    }

    /// The display size.
    pub fn display_size(&self) -> [u32; 2] {
        self.display_size_px
    }

    /// The current target (after the first frame).
    pub fn target(&self) -> Option<&RenderTarget> {
        self.target.as_ref()
    }

    /// Increments whenever the target is remade (so a window re-registers its texture).
    pub fn target_generation(&self) -> u64 {
        self.target_generation
    }
}

impl FrameRenderer for OffscreenStereo {
    fn render(
        &mut self,
        scene: &Scene,
        views: &StereoViews,
        output: &OutputSettings,
        frame_index: u64,
    ) -> Result<(), String> {
        let composition = compose(views, output, self.display_size_px);
        let [w, h] = composition.output_size_px;
        let remake = self
            .target
            .as_ref()
            .is_none_or(|t| t.width() != w || t.height() != h);
        if remake {
            self.target = Some(
                self.renderer
                    .create_target(w, h)
                    .map_err(|e| e.to_string())?,
            );
            self.target_generation += 1;
        }
        let Some(target) = self.target.as_ref() else {
            return Err("no render target".into());
        };
        self.renderer.prepare(scene);
        self.renderer
            .draw_composition(target, &composition, frame_index)
            .map_err(|e| e.to_string())?;
        if self.capture {
            self.last_image = Some(
                self.renderer
                    .read_image(target)
                    .map_err(|e| e.to_string())?,
            );
        } else {
            self.renderer.wait_idle().map_err(|e| e.to_string())?;
        }
        Ok(())
    }
}
