//! Offscreen capture: reading a render target back into memory (rows padded to 256 bytes on
//! the GPU side) and saving or loading PNGs (written atomically).

use std::path::Path;

use super::renderer::{RenderError, RenderTarget, Renderer};

/// An 8-bit RGBA image, rows top to bottom, no padding. Colour values are as stored in the
/// target (sRGB-encoded for an sRGB target, which is what a PNG holds).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RgbaImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width * height * 4` bytes.
    pub pixels: Vec<u8>,
}

/// Failure to load a PNG.
#[derive(Debug, thiserror::Error)]
pub enum PngLoadError {
    /// The file could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// The file.
        path: std::path::PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The bytes are not a PNG we can use.
    #[error("{path} is not a usable PNG: {message}")]
    Decode {
        /// The file.
        path: std::path::PathBuf,
        /// What the decoder said.
        message: String,
    },
}

impl RgbaImage {
    /// The RGBA of pixel (x, y), `None` outside the image.
    pub fn pixel(&self, x: u32, y: u32) -> Option<[u8; 4]> {
        if x >= self.width || y >= self.height {
            return None;
        }
        let i = ((y * self.width + x) * 4) as usize;
        self.pixels
            .get(i..i + 4)
            .and_then(|p| <[u8; 4]>::try_from(p).ok())
    }

    /// PNG bytes of this image.
    pub fn encode_png(&self) -> Result<Vec<u8>, String> {
        let mut out = Vec::new();
        {
            let mut encoder = png::Encoder::new(&mut out, self.width, self.height);
            encoder.set_color(png::ColorType::Rgba);
            encoder.set_depth(png::BitDepth::Eight);
            let mut writer = encoder.write_header().map_err(|e| e.to_string())?;
            writer
                .write_image_data(&self.pixels)
                .map_err(|e| e.to_string())?;
            writer.finish().map_err(|e| e.to_string())?;
        }
        Ok(out)
    }

    /// Saves as PNG, atomically.
    pub fn save_png(&self, path: &Path) -> Result<(), RenderError> {
        let bytes = self.encode_png().map_err(|message| RenderError::Png {
            path: path.to_path_buf(),
            message,
        })?;
        crate::files::write_atomic(path, &bytes)?;
        Ok(())
    }

    /// Loads an 8-bit RGB or RGBA PNG (RGB gets alpha 255).
    pub fn load_png(path: &Path) -> Result<Self, PngLoadError> {
        let bytes = std::fs::read(path).map_err(|source| PngLoadError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::decode_png(&bytes).map_err(|message| PngLoadError::Decode {
            path: path.to_path_buf(),
            message,
        })
    }

    /// Decodes PNG bytes (8-bit RGB or RGBA).
    pub fn decode_png(bytes: &[u8]) -> Result<Self, String> {
        let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
        let mut reader = decoder.read_info().map_err(|e| e.to_string())?;
        let size = reader
            .output_buffer_size()
            .ok_or_else(|| "image too large".to_owned())?;
        let mut buf = vec![0u8; size];
        let info = reader.next_frame(&mut buf).map_err(|e| e.to_string())?;
        if info.bit_depth != png::BitDepth::Eight {
            return Err(format!("bit depth {:?}, need 8", info.bit_depth));
        }
        let data = &buf[..info.buffer_size()];
        let pixels = match info.color_type {
            png::ColorType::Rgba => data.to_vec(),
            png::ColorType::Rgb => data
                .chunks_exact(3)
                .flat_map(|p| [p[0], p[1], p[2], 255])
                .collect(),
            other => return Err(format!("colour type {other:?}, need RGB or RGBA")),
        };
        if pixels.len() != (info.width as usize) * (info.height as usize) * 4 {
            return Err("pixel data size does not match the header".to_owned());
        }
        Ok(Self {
            width: info.width,
            height: info.height,
            pixels,
        })
    }
}

/// Bytes per row of a texture-to-buffer copy: `width * 4` rounded up to 256.
pub fn padded_bytes_per_row(width: u32) -> u32 {
    (width * 4).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT)
}

impl Renderer {
    /// Copies the target's colour texture back to memory (waits for the GPU).
    pub fn read_image(&self, target: &RenderTarget) -> Result<RgbaImage, RenderError> {
        self.read_texture(&target.color)
    }

    /// Copies back what [`RenderTarget::color_view`] shows (on GL its own copy of the colour
    /// texture, refreshed by every draw; elsewhere the colour texture itself): the same bytes
    /// as [`Self::read_image`] after any draw.
    pub fn read_shown_image(&self, target: &RenderTarget) -> Result<RgbaImage, RenderError> {
        self.read_texture(target.shown_texture())
    }

    fn read_texture(&self, texture: &wgpu::Texture) -> Result<RgbaImage, RenderError> {
        let format = texture.format();
        if !matches!(
            format,
            wgpu::TextureFormat::Rgba8Unorm | wgpu::TextureFormat::Rgba8UnormSrgb
        ) {
            return Err(RenderError::UnsupportedReadbackFormat(format));
        }
        let (width, height) = (texture.width(), texture.height());
        let padded = padded_bytes_per_row(width);
        let buffer = self.device().create_buffer(&wgpu::BufferDescriptor {
            label: Some("leman readback"),
            size: u64::from(padded) * u64::from(height),
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let mut encoder = self
            .device()
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("leman readback"),
            });
        encoder.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(padded),
                    rows_per_image: Some(height),
                },
            },
            wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
        );
        self.queue().submit([encoder.finish()]);
        let (sender, receiver) = std::sync::mpsc::channel();
        buffer.slice(..).map_async(wgpu::MapMode::Read, move |r| {
            let _ = sender.send(r);
        });
        self.wait_idle()?;
        receiver
            .recv()
            .map_err(|e| RenderError::Readback(e.to_string()))?
            .map_err(|e| RenderError::Readback(e.to_string()))?;
        let mut pixels = Vec::with_capacity((width * height * 4) as usize);
        {
            let view = buffer
                .slice(..)
                .get_mapped_range()
                .map_err(|e| RenderError::Readback(e.to_string()))?;
            for row in view.chunks(padded as usize).take(height as usize) {
                pixels.extend_from_slice(&row[..(width * 4) as usize]);
            }
        }
        buffer.unmap();
        Ok(RgbaImage {
            width,
            height,
            pixels,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_round_trip_and_padding() {
        assert_eq!(padded_bytes_per_row(1), 256);
        assert_eq!(padded_bytes_per_row(64), 256);
        assert_eq!(padded_bytes_per_row(65), 512);
        assert_eq!(padded_bytes_per_row(320), 1280);
        let img = RgbaImage {
            width: 3,
            height: 2,
            pixels: (0..24).collect(),
        };
        let back = RgbaImage::decode_png(&img.encode_png().expect("encode")).expect("decode");
        assert_eq!(back, img);
        assert_eq!(img.pixel(2, 1), Some([20, 21, 22, 23]));
        assert_eq!(img.pixel(3, 0), None);
        assert!(RgbaImage::decode_png(b"not a png").is_err());
    }
}
