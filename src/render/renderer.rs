//! The wgpu renderer: uploads a frame's [`FrameGeometry`] and draws it once per [`DrawPass`]
//! into a [`RenderTarget`]. Each pass brings its own `clip_from_world` (made by the stereo
//! module), viewport, colour write mask and row parity, so every stereo composition
//! (side-by-side, top-bottom, anaglyph, row-interleaved, frame-sequential, mono) is a list of
//! passes, executed literally ([`Renderer::draw_composition`]); the renderer holds no projection
//! math.
//!
//! Each eye pass is its own wgpu render pass, clearing colour and depth when the recipe says so
//! (the stereo recipes clear depth before every eye, so eyes drawn over the same pixels, as in
//! anaglyph and row-interleaved modes, never depth-test against each other). Row parity is a
//! fragment discard on `floor(position.y) % 2`; the colour mask is the pipeline's write mask.

use std::collections::HashMap;

use glam::{Mat4, Vec3};

use super::batch::{FrameGeometry, LineVertex, LitVertex, SanitizeCounts};
use super::scene::{Rgba, Scene};

/// The WGSL source of the scene shaders.
pub const SCENE_SHADER: &str = include_str!("../../shaders/scene.wgsl");

/// Depth buffer format.
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// Most eye passes in one frame (uniform slots).
pub const MAX_PASSES: usize = 8;

/// Uniform slot stride (wgpu's minimum dynamic-offset alignment is at most 256).
const UNIFORM_STRIDE: u64 = 256;

pub use crate::stereo::{ColorMask, Parity, ViewportPx};

/// One eye drawn into part of the target: the renderer's execution form of a
/// [`crate::stereo::EyePass`] (see [`DrawPass::from_stereo`]), also usable on its own (tests,
/// thumbnails) with any camera matrix.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DrawPass {
    /// The eye's projection times view, wgpu clip conventions (from the stereo module).
    pub clip_from_world: Mat4,
    /// The eye's position in the world (headlight and two-sided lighting), metres.
    pub eye_position_world: Vec3,
    /// Where in the target this eye goes (origin top-left).
    pub viewport: ViewportPx,
    /// Channels written.
    pub color_mask: ColorMask,
    /// Only target rows of this parity (counted from the top, row 0 even) are written.
    pub row_parity: Option<Parity>,
    /// Clear the whole colour attachment to the background before this pass.
    pub clear_color: bool,
    /// Clear the whole depth attachment before this pass.
    pub clear_depth: bool,
}

impl DrawPass {
    /// The stereo recipe's pass as the renderer executes it (frame parity is resolved by
    /// [`crate::stereo::Composition::passes_for_frame`] before this).
    pub fn from_stereo(pass: &crate::stereo::EyePass) -> Self {
        Self {
            clip_from_world: pass.view.clip_from_world,
            eye_position_world: pass.view.position_m,
            viewport: pass.viewport,
            color_mask: pass.color_mask,
            row_parity: pass.row_parity,
            clear_color: pass.clear_color,
            clear_depth: pass.clear_depth,
        }
    }

    /// A single full-target pass with every channel and row, clearing first (mono images).
    pub fn full(clip_from_world: Mat4, eye_position_world: Vec3, width: u32, height: u32) -> Self {
        Self {
            clip_from_world,
            eye_position_world,
            viewport: ViewportPx {
                x: 0,
                y: 0,
                width,
                height,
            },
            color_mask: ColorMask::ALL,
            row_parity: None,
            clear_color: true,
            clear_depth: true,
        }
    }
}

fn color_writes(mask: ColorMask) -> wgpu::ColorWrites {
    let mut w = wgpu::ColorWrites::empty();
    for (on, bit) in [
        (mask.red, wgpu::ColorWrites::RED),
        (mask.green, wgpu::ColorWrites::GREEN),
        (mask.blue, wgpu::ColorWrites::BLUE),
        (mask.alpha, wgpu::ColorWrites::ALPHA),
    ] {
        if on {
            w |= bit;
        }
    }
    w
}

/// Renderer settings fixed at creation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RendererOptions {
    /// Colour format of render targets (RGBA8 sRGB for PNGs and egui images).
    pub color_format: wgpu::TextureFormat,
    /// MSAA samples: 1 (off) or 4.
    pub msaa_samples: u32,
}

impl Default for RendererOptions {
    fn default() -> Self {
        Self {
            color_format: wgpu::TextureFormat::Rgba8UnormSrgb,
            msaa_samples: 1,
        }
    }
}

/// Rendering failures.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// More eye passes than uniform slots.
    #[error("{0} eye passes in one frame; at most {MAX_PASSES} are supported")]
    TooManyPasses(usize),
    /// The recipe was made for another output size than the target's.
    #[error("composition is for a {recipe:?} output but the target is {target:?}")]
    TargetSizeMismatch {
        /// The recipe's output size.
        recipe: [u32; 2],
        /// The target's size.
        target: [u32; 2],
    },
    /// A viewport lies (partly) outside the target or is empty.
    #[error("viewport {viewport:?} does not fit in the {width}×{height} target")]
    BadViewport {
        /// The viewport.
        viewport: ViewportPx,
        /// Target width.
        width: u32,
        /// Target height.
        height: u32,
    },
    /// An eye's matrix or position is not finite: the pass is refused (keep the last good view).
    #[error("eye pass {0} has a non-finite clip_from_world or eye position")]
    NonFiniteEye(usize),
    /// A target of zero size or above the device's limit.
    #[error("render target size {width}×{height} is not supported (max {max})")]
    BadTargetSize {
        /// Asked width.
        width: u32,
        /// Asked height.
        height: u32,
        /// Device limit.
        max: u32,
    },
    /// MSAA sample count other than 1 or 4.
    #[error("MSAA sample count {0} is not supported (use 1 or 4)")]
    BadSampleCount(u32),
    /// Reading pixels back failed.
    #[error("reading the rendered image back failed: {0}")]
    Readback(String),
    /// The target's format cannot be read back as RGBA8.
    #[error("cannot read back a {0:?} target as RGBA8")]
    UnsupportedReadbackFormat(wgpu::TextureFormat),
    /// PNG encoding failed.
    #[error("PNG encoding of {path} failed: {message}")]
    Png {
        /// The file.
        path: std::path::PathBuf,
        /// What the encoder said.
        message: String,
    },
    /// Writing a file failed.
    #[error(transparent)]
    Write(#[from] crate::files::WriteError),
}

/// A colour texture (plus depth and optional MSAA buffer) to render into.
#[derive(Debug)]
pub struct RenderTarget {
    /// The resolved colour texture (RENDER_ATTACHMENT | COPY_SRC | TEXTURE_BINDING).
    pub color: wgpu::Texture,
    /// The view to show the image with (e.g. registered as an egui texture): it reads the
    /// stored sRGB bytes as gamma-encoded values (RGBA8 unorm), which is what egui expects of
    /// a texture. Sampling it in a shader of your own gives sRGB values. Where the backend can
    /// reinterpret a texture's format (Vulkan, Metal, DX12) it is a unorm view of
    /// [`Self::color`]; on GL, which cannot, it views a unorm copy that every draw refreshes.
    pub color_view: wgpu::TextureView,
    /// The unorm copy behind [`Self::color_view`] on backends without view reinterpretation.
    gamma_copy: Option<wgpu::Texture>,
    /// The view drawn into (the texture's own, sRGB, format: shaders write linear light).
    attachment_view: wgpu::TextureView,
    depth_view: wgpu::TextureView,
    msaa_view: Option<wgpu::TextureView>,
    width: u32,
    height: u32,
}

impl RenderTarget {
    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Colour format.
    pub fn format(&self) -> wgpu::TextureFormat {
        self.color.format()
    }

    /// Whether [`Self::color_view`] views a copy of [`Self::color`] (GL) rather than the
    /// texture itself.
    pub fn shows_a_copy(&self) -> bool {
        self.gamma_copy.is_some()
    }

    /// The texture behind [`Self::color_view`]: the gamma copy where there is one, else
    /// [`Self::color`].
    pub(crate) fn shown_texture(&self) -> &wgpu::Texture {
        self.gamma_copy.as_ref().unwrap_or(&self.color)
    }
}

/// What one frame drew and left out.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FrameReport {
    /// Eye passes executed.
    pub passes: usize,
    /// Triangles drawn per pass (opaque + translucent).
    pub triangles: usize,
    /// Line segments drawn per pass.
    pub segments: usize,
    /// Non-finite data left out while building the frame.
    pub sanitized: SanitizeCounts,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum PipelineKind {
    LitOpaque,
    LitTranslucent,
    Lines,
}

/// A vertex or index buffer that grows (doubling) when a frame needs more room.
#[derive(Debug)]
struct GrowBuffer {
    buffer: Option<wgpu::Buffer>,
    usage: wgpu::BufferUsages,
    label: &'static str,
    len_bytes: u64,
}

impl GrowBuffer {
    fn new(label: &'static str, usage: wgpu::BufferUsages) -> Self {
        Self {
            buffer: None,
            usage: usage | wgpu::BufferUsages::COPY_DST,
            label,
            len_bytes: 0,
        }
    }

    fn upload(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, bytes: &[u8]) {
        self.len_bytes = bytes.len() as u64;
        if bytes.is_empty() {
            return;
        }
        let needed = (bytes.len() as u64).next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT);
        let too_small = self.buffer.as_ref().is_none_or(|b| b.size() < needed);
        if too_small {
            self.buffer = Some(device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(self.label),
                size: needed.next_power_of_two().max(1024),
                usage: self.usage,
                mapped_at_creation: false,
            }));
        }
        if let Some(buffer) = &self.buffer {
            if (bytes.len() as u64).is_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT) {
                queue.write_buffer(buffer, 0, bytes);
            } else {
                let mut padded = bytes.to_vec();
                padded.resize(needed as usize, 0);
                queue.write_buffer(buffer, 0, &padded);
            }
        }
    }

    fn slice(&self) -> Option<wgpu::BufferSlice<'_>> {
        match &self.buffer {
            Some(b) if self.len_bytes > 0 => Some(b.slice(..self.len_bytes)),
            _ => None,
        }
    }
}

#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct PassUniforms {
    clip_from_world: [[f32; 4]; 4],
    eye_position_world: [f32; 4],
    key_light_direction: [f32; 4],
    row_filter: [u32; 4],
}

/// Uploaded geometry of the current frame.
#[derive(Debug)]
struct FrameBuffers {
    opaque_vertices: GrowBuffer,
    opaque_indices: GrowBuffer,
    translucent_vertices: GrowBuffer,
    translucent_indices: GrowBuffer,
    lines: GrowBuffer,
    opaque_index_count: u32,
    translucent_index_count: u32,
    line_vertex_count: u32,
}

/// The scene renderer. Holds a device and queue (cheap clones of the caller's), its pipelines
/// and the buffers of the current frame.
#[derive(Debug)]
pub struct Renderer {
    device: wgpu::Device,
    queue: wgpu::Queue,
    options: RendererOptions,
    shader: wgpu::ShaderModule,
    pipeline_layout: wgpu::PipelineLayout,
    uniform_buffer: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    pipelines: HashMap<(PipelineKind, wgpu::ColorWrites, bool), wgpu::RenderPipeline>,
    frame: FrameBuffers,
    background: Rgba,
    key_light_direction: Vec3,
    last_report: FrameReport,
}

impl Renderer {
    /// A renderer on the caller's device (headless: [`super::GpuContext`]; in the window:
    /// eframe's `RenderState`).
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        options: RendererOptions,
    ) -> Result<Self, RenderError> {
        if !matches!(options.msaa_samples, 1 | 4) {
            return Err(RenderError::BadSampleCount(options.msaa_samples));
        }
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("leman scene.wgsl"),
            source: wgpu::ShaderSource::Wgsl(SCENE_SHADER.into()),
        });
        let bind_group_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("leman pass uniforms"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: true,
                    min_binding_size: wgpu::BufferSize::new(
                        std::mem::size_of::<PassUniforms>() as u64
                    ),
                },
                count: None,
            }],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("leman scene"),
            bind_group_layouts: &[Some(&bind_group_layout)],
            immediate_size: 0,
        });
        let uniform_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("leman pass uniforms"),
            size: UNIFORM_STRIDE * MAX_PASSES as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("leman pass uniforms"),
            layout: &bind_group_layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                    buffer: &uniform_buffer,
                    offset: 0,
                    size: wgpu::BufferSize::new(std::mem::size_of::<PassUniforms>() as u64),
                }),
            }],
        });
        let vertex = wgpu::BufferUsages::VERTEX;
        let index = wgpu::BufferUsages::INDEX;
        Ok(Self {
            device: device.clone(),
            queue: queue.clone(),
            options,
            shader,
            pipeline_layout,
            uniform_buffer,
            bind_group,
            pipelines: HashMap::new(),
            frame: FrameBuffers {
                opaque_vertices: GrowBuffer::new("leman opaque vertices", vertex),
                opaque_indices: GrowBuffer::new("leman opaque indices", index),
                translucent_vertices: GrowBuffer::new("leman translucent vertices", vertex),
                translucent_indices: GrowBuffer::new("leman translucent indices", index),
                lines: GrowBuffer::new("leman lines", vertex),
                opaque_index_count: 0,
                translucent_index_count: 0,
                line_vertex_count: 0,
            },
            background: Rgba::BACKGROUND,
            key_light_direction: Vec3::Y,
            last_report: FrameReport::default(),
        })
    }

    /// The options this renderer was made with.
    pub fn options(&self) -> RendererOptions {
        self.options
    }

    /// The device.
    pub fn device(&self) -> &wgpu::Device {
        &self.device
    }

    /// Largest render target width and height this device allows, pixels.
    pub fn max_target_px(&self) -> u32 {
        self.device.limits().max_texture_dimension_2d
    }

    /// A render target of `width × height` pixels in this renderer's colour format.
    pub fn create_target(&self, width: u32, height: u32) -> Result<RenderTarget, RenderError> {
        let max = self.max_target_px();
        if width == 0 || height == 0 || width > max || height > max {
            return Err(RenderError::BadTargetSize { width, height, max });
        }
        let size = wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        };
        let samples = self.options.msaa_samples;
        let gamma_format = self.options.color_format.remove_srgb_suffix();
        // Without view reinterpretation (GL) the gamma view is of a unorm copy, refreshed by a
        // texture copy (sRGB and unorm RGBA8 are copy-compatible) at the end of every draw.
        let reinterpret = gamma_format == self.options.color_format
            || super::device_caps::reinterprets_texture_formats(&self.device);
        let reinterpreted = [gamma_format];
        let color = self.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("leman colour"),
            size,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: self.options.color_format,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::COPY_SRC
                | wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: if reinterpret { &reinterpreted } else { &[] },
        });
        let gamma_copy = (!reinterpret).then(|| {
            self.device.create_texture(&wgpu::TextureDescriptor {
                label: Some("leman colour (gamma copy)"),
                size,
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: gamma_format,
                usage: wgpu::TextureUsages::COPY_DST
                    | wgpu::TextureUsages::COPY_SRC
                    | wgpu::TextureUsages::TEXTURE_BINDING,
                view_formats: &[],
            })
        });
        let depth = self.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("leman depth"),
            size,
            mip_level_count: 1,
            sample_count: samples,
            dimension: wgpu::TextureDimension::D2,
            format: DEPTH_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            view_formats: &[],
        });
        let msaa_view = (samples > 1).then(|| {
            self.device
                .create_texture(&wgpu::TextureDescriptor {
                    label: Some("leman colour msaa"),
                    size,
                    mip_level_count: 1,
                    sample_count: samples,
                    dimension: wgpu::TextureDimension::D2,
                    format: self.options.color_format,
                    usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
                    view_formats: &[],
                })
                .create_view(&wgpu::TextureViewDescriptor::default())
        });
        let color_view = match &gamma_copy {
            Some(copy) => copy.create_view(&wgpu::TextureViewDescriptor::default()),
            None => color.create_view(&wgpu::TextureViewDescriptor {
                label: Some("leman colour (gamma view)"),
                format: Some(gamma_format),
                ..Default::default()
            }),
        };
        Ok(RenderTarget {
            attachment_view: color.create_view(&wgpu::TextureViewDescriptor::default()),
            color_view,
            gamma_copy,
            color,
            depth_view: depth.create_view(&wgpu::TextureViewDescriptor::default()),
            msaa_view,
            width,
            height,
        })
    }

    /// CPU part of a frame: builds the geometry from the scene (leaving out non-finite data)
    /// and uploads it. Returns what was left out.
    pub fn prepare(&mut self, scene: &Scene) -> SanitizeCounts {
        let geometry = FrameGeometry::build(scene);
        self.upload(&geometry);
        self.background = scene.background;
        self.key_light_direction = scene.key_light_direction;
        geometry.sanitized
    }

    /// Uploads already-built geometry (every float in it must be finite: built by
    /// [`FrameGeometry::build`]).
    pub fn upload(&mut self, geometry: &FrameGeometry) {
        let f = &mut self.frame;
        let (d, q) = (&self.device, &self.queue);
        f.opaque_vertices.upload(
            d,
            q,
            bytemuck::cast_slice::<LitVertex, u8>(&geometry.opaque.vertices),
        );
        f.opaque_indices
            .upload(d, q, bytemuck::cast_slice(&geometry.opaque.indices));
        f.translucent_vertices.upload(
            d,
            q,
            bytemuck::cast_slice::<LitVertex, u8>(&geometry.translucent.vertices),
        );
        f.translucent_indices
            .upload(d, q, bytemuck::cast_slice(&geometry.translucent.indices));
        f.lines.upload(
            d,
            q,
            bytemuck::cast_slice::<LineVertex, u8>(&geometry.lines),
        );
        f.opaque_index_count = geometry.opaque.indices.len() as u32;
        f.translucent_index_count = geometry.translucent.indices.len() as u32;
        f.line_vertex_count = geometry.lines.len() as u32;
        self.last_report = FrameReport {
            passes: 0,
            triangles: geometry.opaque.indices.len() / 3 + geometry.translucent.indices.len() / 3,
            segments: geometry.lines.len() / 2,
            sanitized: geometry.sanitized,
        };
    }

    /// GPU part of a frame: executes the stereo recipe for presented frame `frame_index`
    /// (frame-sequential modes alternate eyes) with the prepared geometry. The recipe's output
    /// size must be the target's.
    pub fn draw_composition(
        &mut self,
        target: &RenderTarget,
        composition: &crate::stereo::Composition,
        frame_index: u64,
    ) -> Result<FrameReport, RenderError> {
        let target_size = [target.width, target.height];
        if composition.output_size_px != target_size {
            return Err(RenderError::TargetSizeMismatch {
                recipe: composition.output_size_px,
                target: target_size,
            });
        }
        let passes: Vec<DrawPass> = composition
            .passes_for_frame(frame_index)
            .map(DrawPass::from_stereo)
            .collect();
        self.draw(target, &passes)
    }

    /// GPU part of a frame: draws the prepared geometry once per pass into `target` and submits
    /// the work (it does not wait for it). A pass with `clear_color` clears to the scene's
    /// background; an empty pass list just clears.
    pub fn draw(
        &mut self,
        target: &RenderTarget,
        passes: &[DrawPass],
    ) -> Result<FrameReport, RenderError> {
        if passes.len() > MAX_PASSES {
            return Err(RenderError::TooManyPasses(passes.len()));
        }
        for (i, p) in passes.iter().enumerate() {
            let v = p.viewport;
            let fits = v.width > 0
                && v.height > 0
                && u64::from(v.x) + u64::from(v.width) <= u64::from(target.width)
                && u64::from(v.y) + u64::from(v.height) <= u64::from(target.height);
            if !fits {
                return Err(RenderError::BadViewport {
                    viewport: v,
                    width: target.width,
                    height: target.height,
                });
            }
            if !(p.clip_from_world.is_finite() && p.eye_position_world.is_finite()) {
                return Err(RenderError::NonFiniteEye(i));
            }
        }
        // Uniforms for every pass, one 256-byte slot each.
        let key = self.key_light_direction.normalize_or(Vec3::Y);
        let mut bytes = vec![0u8; UNIFORM_STRIDE as usize * passes.len().max(1)];
        for (i, p) in passes.iter().enumerate() {
            let u = PassUniforms {
                clip_from_world: p.clip_from_world.to_cols_array_2d(),
                eye_position_world: p.eye_position_world.extend(1.0).to_array(),
                key_light_direction: key.extend(0.0).to_array(),
                row_filter: [
                    match p.row_parity {
                        None => 0,
                        Some(Parity::Even) => 1,
                        Some(Parity::Odd) => 2,
                    },
                    0,
                    0,
                    0,
                ],
            };
            let at = i * UNIFORM_STRIDE as usize;
            bytes[at..at + std::mem::size_of::<PassUniforms>()]
                .copy_from_slice(bytemuck::bytes_of(&u));
        }
        self.queue.write_buffer(&self.uniform_buffer, 0, &bytes);
        for p in passes {
            for kind in [
                PipelineKind::LitOpaque,
                PipelineKind::Lines,
                PipelineKind::LitTranslucent,
            ] {
                self.ensure_pipeline(kind, color_writes(p.color_mask), p.row_parity.is_some());
            }
        }
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("leman frame"),
            });
        let bg = self.background.to_sanitized_array().map(f64::from);
        let clear = wgpu::Color {
            r: bg[0],
            g: bg[1],
            b: bg[2],
            a: 1.0,
        };
        let (attachment_view, resolve_target) = match &target.msaa_view {
            Some(msaa) => (msaa, Some(&target.attachment_view)),
            None => (&target.attachment_view, None),
        };
        let pass_count = passes.len().max(1);
        for i in 0..pass_count {
            let (clear_color, clear_depth) = passes
                .get(i)
                .map_or((true, true), |p| (p.clear_color, p.clear_depth));
            let load = if clear_color {
                wgpu::LoadOp::Clear(clear)
            } else {
                wgpu::LoadOp::Load
            };
            let mut rp = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("leman eye pass"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: attachment_view,
                    depth_slice: None,
                    resolve_target,
                    ops: wgpu::Operations {
                        load,
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &target.depth_view,
                    depth_ops: Some(wgpu::Operations {
                        load: if clear_depth {
                            wgpu::LoadOp::Clear(1.0)
                        } else {
                            wgpu::LoadOp::Load
                        },
                        store: wgpu::StoreOp::Store,
                    }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            let Some(p) = passes.get(i) else {
                continue;
            };
            let v = p.viewport;
            rp.set_viewport(
                v.x as f32,
                v.y as f32,
                v.width as f32,
                v.height as f32,
                0.0,
                1.0,
            );
            rp.set_scissor_rect(v.x, v.y, v.width, v.height);
            rp.set_bind_group(0, &self.bind_group, &[(i as u64 * UNIFORM_STRIDE) as u32]);
            let f = &self.frame;
            let draws = [
                (
                    PipelineKind::LitOpaque,
                    f.opaque_vertices.slice(),
                    f.opaque_indices.slice(),
                    f.opaque_index_count,
                ),
                (
                    PipelineKind::Lines,
                    f.lines.slice(),
                    None,
                    f.line_vertex_count,
                ),
                (
                    PipelineKind::LitTranslucent,
                    f.translucent_vertices.slice(),
                    f.translucent_indices.slice(),
                    f.translucent_index_count,
                ),
            ];
            for (kind, vertices, indices, count) in draws {
                let (Some(pipeline), Some(vertices)) = (
                    self.pipelines
                        .get(&(kind, color_writes(p.color_mask), p.row_parity.is_some())),
                    vertices,
                ) else {
                    continue;
                };
                if count == 0 {
                    continue;
                }
                rp.set_pipeline(pipeline);
                rp.set_vertex_buffer(0, vertices);
                match indices {
                    Some(indices) => {
                        rp.set_index_buffer(indices, wgpu::IndexFormat::Uint32);
                        rp.draw_indexed(0..count, 0, 0..1);
                    }
                    None => rp.draw(0..count, 0..1),
                }
            }
        }
        if let Some(copy) = &target.gamma_copy {
            encoder.copy_texture_to_texture(
                target.color.as_image_copy(),
                copy.as_image_copy(),
                target.color.size(),
            );
        }
        self.queue.submit([encoder.finish()]);
        self.last_report.passes = passes.len();
        Ok(self.last_report)
    }

    /// A whole frame: [`Self::prepare`] then [`Self::draw`].
    pub fn render(
        &mut self,
        target: &RenderTarget,
        scene: &Scene,
        passes: &[DrawPass],
    ) -> Result<FrameReport, RenderError> {
        self.prepare(scene);
        self.draw(target, passes)
    }

    /// Blocks until the GPU has finished all submitted work.
    pub fn wait_idle(&self) -> Result<(), RenderError> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| RenderError::Readback(e.to_string()))
    }

    pub(crate) fn queue(&self) -> &wgpu::Queue {
        &self.queue
    }

    fn ensure_pipeline(&mut self, kind: PipelineKind, mask: wgpu::ColorWrites, rows: bool) {
        if self.pipelines.contains_key(&(kind, mask, rows)) {
            return;
        }
        let lit_attributes =
            wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x4];
        let line_attributes = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x4];
        let (vs, fs, layout, topology) = match kind {
            PipelineKind::LitOpaque | PipelineKind::LitTranslucent => (
                "vs_lit",
                if rows { "fs_lit_rows" } else { "fs_lit" },
                wgpu::VertexBufferLayout {
                    array_stride: std::mem::size_of::<LitVertex>() as u64,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &lit_attributes,
                },
                wgpu::PrimitiveTopology::TriangleList,
            ),
            PipelineKind::Lines => (
                "vs_line",
                if rows { "fs_line_rows" } else { "fs_line" },
                wgpu::VertexBufferLayout {
                    array_stride: std::mem::size_of::<LineVertex>() as u64,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &line_attributes,
                },
                wgpu::PrimitiveTopology::LineList,
            ),
        };
        let translucent = kind == PipelineKind::LitTranslucent;
        let pipeline = self
            .device
            .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("leman scene pipeline"),
                layout: Some(&self.pipeline_layout),
                vertex: wgpu::VertexState {
                    module: &self.shader,
                    entry_point: Some(vs),
                    compilation_options: Default::default(),
                    buffers: &[Some(layout)],
                },
                primitive: wgpu::PrimitiveState {
                    topology,
                    // Two-sided: meshes from the simulation need not have consistent winding.
                    cull_mode: None,
                    ..Default::default()
                },
                depth_stencil: Some(wgpu::DepthStencilState {
                    format: DEPTH_FORMAT,
                    depth_write_enabled: Some(!translucent),
                    depth_compare: Some(wgpu::CompareFunction::LessEqual),
                    stencil: wgpu::StencilState::default(),
                    bias: wgpu::DepthBiasState::default(),
                }),
                multisample: wgpu::MultisampleState {
                    count: self.options.msaa_samples,
                    ..Default::default()
                },
                fragment: Some(wgpu::FragmentState {
                    module: &self.shader,
                    entry_point: Some(fs),
                    compilation_options: Default::default(),
                    targets: &[Some(wgpu::ColorTargetState {
                        format: self.options.color_format,
                        blend: translucent.then_some(wgpu::BlendState::ALPHA_BLENDING),
                        write_mask: mask,
                    })],
                }),
                multiview_mask: None,
                cache: None,
            });
        self.pipelines.insert((kind, mask, rows), pipeline);
    }
}
