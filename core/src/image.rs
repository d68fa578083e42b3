//! RGB images as f32 in [0, 1], read from and written to PNG or JPEG, and pixel rectangles
//! ([`Rect`]) within them.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::files::write_atomic;

/// A pixel rectangle `[x, y, w, h]` (AD-NeRF's `face_rect`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(from = "[i64; 4]", into = "[i64; 4]")]
pub struct Rect {
    pub x: i64,
    pub y: i64,
    pub w: i64,
    pub h: i64,
}

impl From<[i64; 4]> for Rect {
    fn from([x, y, w, h]: [i64; 4]) -> Self {
        Rect { x, y, w, h }
    }
}

impl From<Rect> for [i64; 4] {
    fn from(r: Rect) -> Self {
        [r.x, r.y, r.w, r.h]
    }
}

impl Rect {
    /// The rectangle cut to a `width` x `height` image; `None` if nothing is left.
    pub fn clipped(&self, width: u32, height: u32) -> Option<Rect> {
        let x0 = self.x.max(0);
        let y0 = self.y.max(0);
        let x1 = self.x.saturating_add(self.w).min(width as i64);
        let y1 = self.y.saturating_add(self.h).min(height as i64);
        (x1 > x0 && y1 > y0).then_some(Rect {
            x: x0,
            y: y0,
            w: x1 - x0,
            h: y1 - y0,
        })
    }

    /// True if pixel (`i`, `j`) lies inside.
    pub fn contains(&self, i: u32, j: u32) -> bool {
        let (i, j) = (i as i64, j as i64);
        i >= self.x
            && i < self.x.saturating_add(self.w)
            && j >= self.y
            && j < self.y.saturating_add(self.h)
    }
}

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

    /// Values that are NaN or infinite (a render that holds any is not a picture).
    pub fn non_finite_values(&self) -> usize {
        self.data.iter().filter(|v| !v.is_finite()).count()
    }

    /// Number of pixels.
    pub fn n_pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// The colours of `pixels` (row-major indices), `[pixels.len(), 3]` flat: what a
    /// renderer composites behind the rays it sends through a network.
    pub fn gather(&self, pixels: &[usize]) -> Vec<f32> {
        let mut out = Vec::with_capacity(3 * pixels.len());
        for &p in pixels {
            out.extend_from_slice(&self.data[3 * p..3 * p + 3]);
        }
        out
    }

    /// Writes colour `r` of `rgb` (`[pixels.len(), 3]` flat) into pixel `pixels[r]` (a
    /// row-major index): rendered rays put back into their image.
    pub fn paint(&mut self, pixels: &[usize], rgb: &[f32]) {
        for (r, &p) in pixels.iter().enumerate() {
            self.data[3 * p..3 * p + 3].copy_from_slice(&rgb[3 * r..3 * r + 3]);
        }
    }

    /// The image `factor` times larger on each side, bilinearly interpolated between pixel
    /// centres (output pixel `x` samples the input at `(x + 0.5) / factor - 0.5`, clamped to
    /// the edge pixels). `factor` 1 (or 0) is a copy.
    pub fn upscaled(&self, factor: u32) -> ImageRgb {
        if factor <= 1 {
            return self.clone();
        }
        let (w, h) = (self.width as usize, self.height as usize);
        let (ow, oh) = (w * factor as usize, h * factor as usize);
        // Per output coordinate: the two input indices and the second one's weight.
        let taps = |n_in: usize, n_out: usize| -> Vec<(usize, usize, f32)> {
            (0..n_out)
                .map(|x| {
                    let u = ((x as f32 + 0.5) / factor as f32 - 0.5).clamp(0.0, (n_in - 1) as f32);
                    let i0 = u.floor() as usize;
                    let i1 = (i0 + 1).min(n_in - 1);
                    (i0, i1, u - i0 as f32)
                })
                .collect()
        };
        let (xs, ys) = (taps(w, ow), taps(h, oh));
        let mut data = Vec::with_capacity(3 * ow * oh);
        for &(j0, j1, ty) in &ys {
            for &(i0, i1, tx) in &xs {
                for c in 0..3 {
                    let at = |i: usize, j: usize| self.data[3 * (j * w + i) + c];
                    let top = at(i0, j0) + tx * (at(i1, j0) - at(i0, j0));
                    let bottom = at(i0, j1) + tx * (at(i1, j1) - at(i0, j1));
                    data.push(top + ty * (bottom - top));
                }
            }
        }
        ImageRgb {
            width: ow as u32,
            height: oh as u32,
            data,
        }
    }

    /// The image `factor` times smaller on each side, each pixel the mean of its `factor x
    /// factor` block (sides not divisible by `factor` lose their last pixels). `factor` 1
    /// (or 0) is a copy.
    pub fn downscaled(&self, factor: u32) -> ImageRgb {
        if factor <= 1 {
            return self.clone();
        }
        let (w, f) = (self.width as usize, factor as usize);
        let (ow, oh) = (w / f, self.height as usize / f);
        let mut data = vec![0.0f32; 3 * ow * oh];
        let scale = 1.0 / (f * f) as f32;
        for y in 0..oh {
            for x in 0..ow {
                for c in 0..3 {
                    let mut sum = 0.0f32;
                    for j in y * f..(y + 1) * f {
                        for i in x * f..(x + 1) * f {
                            sum += self.data[3 * (j * w + i) + c];
                        }
                    }
                    data[3 * (y * ow + x) + c] = sum * scale;
                }
            }
        }
        ImageRgb {
            width: ow as u32,
            height: oh as u32,
            data,
        }
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

/// A colour for `v` in [0, 1] on a dark-blue -> magenta -> orange -> pale-yellow ramp
/// (perceptually ordered, like matplotlib's "inferno"); values outside are clamped.
pub fn heat_color(v: f32) -> [f32; 3] {
    const STOPS: [[f32; 3]; 5] = [
        [0.0, 0.0, 0.016],
        [0.34, 0.06, 0.43],
        [0.73, 0.21, 0.33],
        [0.98, 0.55, 0.04],
        [0.99, 1.0, 0.64],
    ];
    let v = if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
    let x = v * (STOPS.len() - 1) as f32;
    let i = (x.floor() as usize).min(STOPS.len() - 2);
    let t = x - i as f32;
    [0, 1, 2].map(|c| STOPS[i][c] + t * (STOPS[i + 1][c] - STOPS[i][c]))
}

/// The per-pixel error heat map of `a` against `b`: mean absolute RGB difference times
/// `gain`, coloured by [`heat_color`]. Images of different sizes give an error.
pub fn error_map(a: &ImageRgb, b: &ImageRgb, gain: f32) -> Result<ImageRgb> {
    if (a.width, a.height) != (b.width, b.height) {
        return Err(crate::Error::Argument(format!(
            "error map of a {}x{} and a {}x{} image",
            a.width, a.height, b.width, b.height
        )));
    }
    let mut out = ImageRgb::filled(a.width, a.height, [0.0; 3]);
    for (o, (x, y)) in out
        .data
        .chunks_exact_mut(3)
        .zip(a.data.chunks_exact(3).zip(b.data.chunks_exact(3)))
    {
        let e = (0..3).map(|c| (x[c] - y[c]).abs()).sum::<f32>() / 3.0;
        o.copy_from_slice(&heat_color(e * gain));
    }
    Ok(out)
}

/// Tiles images into a grid, row by row, with a `gap`-pixel border of `gap_color`; every
/// cell takes the size of the largest image.
pub fn grid(rows: &[Vec<ImageRgb>], gap: u32, gap_color: [f32; 3]) -> ImageRgb {
    let cell_w = rows.iter().flatten().map(|i| i.width).max().unwrap_or(0);
    let cell_h = rows.iter().flatten().map(|i| i.height).max().unwrap_or(0);
    let n_cols = rows.iter().map(|r| r.len()).max().unwrap_or(0) as u32;
    let width = n_cols * (cell_w + gap) + gap;
    let height = rows.len() as u32 * (cell_h + gap) + gap;
    let mut out = ImageRgb::filled(width, height, gap_color);
    for (r, row) in rows.iter().enumerate() {
        for (c, img) in row.iter().enumerate() {
            let (x0, y0) = (
                gap + c as u32 * (cell_w + gap),
                gap + r as u32 * (cell_h + gap),
            );
            for j in 0..img.height {
                for i in 0..img.width {
                    out.set(x0 + i, y0 + j, img.get(i, j));
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn upscaling_keeps_flat_colours_and_ramps_and_edges() {
        let flat = ImageRgb::filled(3, 2, [0.2, 0.5, 0.9]);
        let up = flat.upscaled(4);
        assert_eq!((up.width, up.height), (12, 8));
        assert!(up.data.chunks(3).all(|p| p == [0.2, 0.5, 0.9]));
        // A horizontal ramp 0, 1, 2, 3 (scaled): interior output pixels interpolate it
        // exactly, those beyond the first and last centres hold the edge value.
        let mut ramp = ImageRgb::filled(4, 1, [0.0; 3]);
        for i in 0..4 {
            ramp.set(i, 0, [i as f32 / 10.0; 3]);
        }
        let up = ramp.upscaled(2);
        let row: Vec<f32> = (0..8).map(|x| up.get(x, 0)[0]).collect();
        let want = [0.0, 0.025, 0.075, 0.125, 0.175, 0.225, 0.275, 0.3];
        for (got, want) in row.iter().zip(want) {
            assert!((got - want).abs() < 1e-6, "{row:?}");
        }
        assert_eq!(ramp.upscaled(1), ramp);
    }
}
