//! RGB images as f32 in [0, 1], read from and written to PNG or JPEG.

use std::path::Path;

use crate::error::{Error, Result, write_atomic};

/// An RGB image, row-major, `data` is `[height, width, 3]` in [0, 1].
#[derive(Debug, Clone, PartialEq)]
pub struct ImageRgb {
    pub width: u32,
    pub height: u32,
    pub data: Vec<f32>,
}

impl ImageRgb {
    /// A `width` x `height` image filled with `rgb`.
    pub fn filled(width: u32, height: u32, rgb: [f32; 3]) -> ImageRgb {
        let n = width as usize * height as usize;
        let mut data = Vec::with_capacity(3 * n);
        for _ in 0..n {
            data.extend_from_slice(&rgb);
        }
        ImageRgb {
            width,
            height,
            data,
        }
    }

    /// The colour at pixel (`i`, `j`).
    pub fn get(&self, i: u32, j: u32) -> [f32; 3] {
        let o = 3 * (j as usize * self.width as usize + i as usize);
        [self.data[o], self.data[o + 1], self.data[o + 2]]
    }

    /// Sets the colour at pixel (`i`, `j`).
    pub fn set(&mut self, i: u32, j: u32, rgb: [f32; 3]) {
        let o = 3 * (j as usize * self.width as usize + i as usize);
        self.data[o..o + 3].copy_from_slice(&rgb);
    }

    /// Number of pixels.
    pub fn n_pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// 8-bit RGB bytes, rounded.
    pub fn to_rgb8(&self) -> Vec<u8> {
        self.data.iter().map(|&v| to_u8(v)).collect()
    }

    /// From 8-bit RGB bytes.
    pub fn from_rgb8(width: u32, height: u32, bytes: &[u8]) -> ImageRgb {
        ImageRgb {
            width,
            height,
            data: bytes.iter().map(|&b| b as f32 / 255.0).collect(),
        }
    }

    /// Reads a PNG or JPEG (any colour type; alpha is dropped, grey is spread to RGB).
    pub fn load(path: &Path) -> Result<ImageRgb> {
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        let img = image::load_from_memory(&bytes)
            .map_err(|e| Error::invalid(path, format!("not a readable image: {e}")))?;
        let rgb = img.to_rgb8();
        Ok(ImageRgb::from_rgb8(rgb.width(), rgb.height(), rgb.as_raw()))
    }

    /// Writes an 8-bit PNG atomically.
    pub fn save_png(&self, path: &Path) -> Result<()> {
        save_png_bytes(
            path,
            self.width,
            self.height,
            image::ExtendedColorType::Rgb8,
            &self.to_rgb8(),
        )
    }
}

/// A float in [0, 1] to an 8-bit value (NaN becomes 0).
pub fn to_u8(v: f32) -> u8 {
    if v.is_nan() {
        0
    } else {
        (v.clamp(0.0, 1.0) * 255.0).round() as u8
    }
}

/// Encodes raw pixel bytes as PNG and writes them atomically.
pub fn save_png_bytes(
    path: &Path,
    width: u32,
    height: u32,
    color: image::ExtendedColorType,
    bytes: &[u8],
) -> Result<()> {
    let mut buf = Vec::new();
    let encoder = image::codecs::png::PngEncoder::new(&mut buf);
    image::ImageEncoder::write_image(encoder, bytes, width, height, color)
        .map_err(|e| Error::invalid(path, format!("cannot encode PNG: {e}")))?;
    write_atomic(path, &buf)
}
