//! Showing the 3D view inside an egui panel: the renderer draws into its own texture (on
//! eframe's device), registered with egui-wgpu as a native texture and shown as an image. This
//! is the only file of the renderer that knows about egui.
//!
//! Rendering to a texture (rather than painting in egui's render pass through a callback) keeps
//! our own depth buffer, MSAA and multi-pass stereo composition, and the same code path as
//! offscreen PNG capture. The texture is sampled with nearest filtering, so an image shown at
//! one texel per physical pixel keeps row-interleaved stereo exact.
//!
//! Typical use inside `eframe::App::ui` (with `frame.wgpu_render_state()`):
//! ```ignore
//! let size_px = [(rect.width() * ppp).round() as u32, (rect.height() * ppp).round() as u32];
//! let recipe = leman::stereo::compose(&views, &output_settings, size_px);
//! let id = view.render(render_state, &scene, &recipe, frame_index)?;
//! ui.image(egui::load::SizedTexture::new(id, rect.size()));
//! ```

use super::renderer::{FrameReport, RenderError, RenderTarget, Renderer, RendererOptions};
use super::scene::Scene;

/// A 3D view shown as an egui image: a [`Renderer`], its target and the egui texture id.
#[derive(Debug)]
pub struct EguiSceneView {
    renderer: Renderer,
    target: Option<RenderTarget>,
    texture_id: Option<egui::TextureId>,
    last_report: FrameReport,
}

impl EguiSceneView {
    /// A view on eframe's (or any egui-wgpu) device. The colour format is RGBA8 sRGB whatever
    /// the window's format, since the result is sampled as a texture.
    pub fn new(
        render_state: &egui_wgpu::RenderState,
        options: RendererOptions,
    ) -> Result<Self, RenderError> {
        Ok(Self {
            renderer: Renderer::new(&render_state.device, &render_state.queue, options)?,
            target: None,
            texture_id: None,
            last_report: FrameReport::default(),
        })
    }

    /// The renderer (e.g. to read the image back for a screenshot).
    pub fn renderer(&self) -> &Renderer {
        &self.renderer
    }

    /// The current target, if something was rendered.
    pub fn target(&self) -> Option<&RenderTarget> {
        self.target.as_ref()
    }

    /// What the last frame drew.
    pub fn last_report(&self) -> FrameReport {
        self.last_report
    }

    /// Renders `scene` with the stereo recipe (its output size decides the texture size; a new
    /// size recreates the texture, keeping the egui id) and returns the texture id to show. The
    /// GPU work is submitted before egui's, so the image is complete when egui paints it.
    pub fn render(
        &mut self,
        render_state: &egui_wgpu::RenderState,
        scene: &Scene,
        composition: &crate::stereo::Composition,
        frame_index: u64,
    ) -> Result<egui::TextureId, RenderError> {
        let [width, height] = composition.output_size_px;
        let resized = self
            .target
            .as_ref()
            .is_none_or(|t| t.width() != width || t.height() != height);
        if resized {
            let target = self.renderer.create_target(width, height)?;
            let mut egui_renderer = render_state.renderer.write();
            let id = match self.texture_id {
                Some(id) => {
                    egui_renderer.update_egui_texture_from_wgpu_texture(
                        &render_state.device,
                        &target.color_view,
                        wgpu::FilterMode::Nearest,
                        id,
                    );
                    id
                }
                None => egui_renderer.register_native_texture(
                    &render_state.device,
                    &target.color_view,
                    wgpu::FilterMode::Nearest,
                ),
            };
            self.texture_id = Some(id);
            self.target = Some(target);
        }
        let (Some(target), Some(id)) = (self.target.as_ref(), self.texture_id) else {
            return Err(RenderError::Readback("view target missing".to_owned()));
        };
        self.renderer.prepare(scene);
        self.last_report = self
            .renderer
            .draw_composition(target, composition, frame_index)?;
        Ok(id)
    }

    /// Frees the egui texture (call when the panel goes away for good).
    pub fn free(&mut self, render_state: &egui_wgpu::RenderState) {
        if let Some(id) = self.texture_id.take() {
            render_state.renderer.write().free_texture(&id);
        }
        self.target = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::reference::reference_scene;
    use crate::stereo::{OutputSettings, StereoMode, compose, eye_views};

    /// The view shows up in an egui frame rendered by egui-wgpu on the same device: the pixel
    /// at the image's centre equals the one the renderer drew.
    #[test]
    fn scene_texture_is_shown_by_egui() {
        if crate::render::GpuContext::new_headless().is_err() {
            assert!(
                !crate::render::device_caps::gpu_required_by_env(),
                "LEMAN_REQUIRE_GPU=1 but no GPU"
            );
            use std::io::Write;
            let _ = writeln!(
                std::io::stderr(),
                "*** SKIPPED scene_texture_is_shown_by_egui: no GPU adapter ***"
            );
            return;
        }
        let render_state = egui_kittest::wgpu::create_render_state(
            egui_kittest::wgpu::default_wgpu_setup(),
            egui_wgpu::RendererOptions::PREDICTABLE,
        );
        let mut view = EguiSceneView::new(&render_state, RendererOptions::default()).expect("view");
        let views = eye_views(
            &crate::calibration::CalibrationProfile::default(),
            &crate::pose::Pose::from_translation(glam::Vec3::new(0.0, 0.0, 0.6)),
            &crate::stereo::ViewSettings::default(),
        )
        .expect("views");
        let settings = OutputSettings {
            mode: StereoMode::SideBySideHalf,
            swap_eyes: false,
        };
        let (w, h) = (160u32, 90u32);
        let recipe = compose(&views, &settings, [w, h]);
        let id = view
            .render(&render_state, &reference_scene(), &recipe, 0)
            .expect("render");
        assert!(view.last_report().triangles > 0);
        let ours = view
            .renderer()
            .read_image(view.target().expect("target"))
            .expect("read");
        // Same size again keeps the id; a new size keeps it too.
        let again = view
            .render(&render_state, &reference_scene(), &recipe, 1)
            .expect("render");
        assert_eq!(again, id);

        let mut harness = egui_kittest::Harness::builder()
            .with_size(egui::vec2(w as f32 + 32.0, h as f32 + 32.0))
            .with_pixels_per_point(1.0)
            .renderer(egui_kittest::wgpu::WgpuTestRenderer::from_render_state(
                render_state.clone(),
            ))
            .build_ui(move |ui| {
                ui.add(
                    egui::Image::new(egui::load::SizedTexture::new(
                        id,
                        egui::vec2(w as f32, h as f32),
                    ))
                    .fit_to_exact_size(egui::vec2(w as f32, h as f32)),
                );
            });
        harness.run();
        let shown = harness.render().expect("egui render");
        // Find our image in egui's frame (egui places it after its panel margin): the offset
        // where most of our drawn pixels reappear.
        let (sx, sy) = (shown.width(), shown.height());
        let bg = ours.pixel(0, 0).expect("bg");
        let drawn_px: Vec<(u32, u32, [u8; 4])> = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .filter_map(|(x, y)| ours.pixel(x, y).map(|p| (x, y, p)))
            .filter(|(_, _, p)| p[..3] != bg[..3])
            .collect();
        let drawn = drawn_px.len();
        let matching = (0..=16u32)
            .flat_map(|dy| (0..=16u32).map(move |dx| (dx, dy)))
            .map(|(dx, dy)| {
                drawn_px
                    .iter()
                    .filter(|(x, y, o)| {
                        let (ex, ey) = (x + dx, y + dy);
                        ex < sx
                            && ey < sy
                            && shown
                                .get_pixel(ex, ey)
                                .0
                                .iter()
                                .zip(o)
                                .take(3)
                                .all(|(a, b)| a.abs_diff(*b) <= 3)
                    })
                    .count()
            })
            .max()
            .unwrap_or(0);
        assert!(drawn > 500, "{drawn}");
        assert!(
            matching * 10 >= drawn * 9,
            "{matching} of {drawn} drawn pixels found in egui's frame"
        );
        view.free(&render_state);
    }
}
