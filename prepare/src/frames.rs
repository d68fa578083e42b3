//! The dataset's image files: the JPEG writer and the readers that check a frame's size.

use std::path::Path;

use crate::error::{Error, Result};

/// The JPEG quality of every frame, head image and background written. AD-NeRF's layout
/// names them `.jpg`, and the models are fitted to them: on the test pattern below one
/// generation at quality 95 keeps 43.5 dB PSNR, a trained model's error of the same order,
/// where 100 keeps 49.7 (chroma is never subsampled).
pub(crate) const JPEG_QUALITY: u8 = 100;

/// Writes `rgb` (`size x size`, RGB bytes) as a JPEG at [`JPEG_QUALITY`].
pub(crate) fn save_jpeg(path: &Path, rgb: &[u8], size: u32) -> Result<()> {
    let file = std::fs::File::create(path).map_err(|e| Error::io(path, e))?;
    let mut w = std::io::BufWriter::new(file);
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut w, JPEG_QUALITY)
        .encode(rgb, size, size, image::ExtendedColorType::Rgb8)
        .map_err(|e| Error::invalid(path, format!("cannot write the JPEG: {e}")))
}

/// The `size x size` image at `path` as RGB bytes.
pub(crate) fn read_rgb(path: &Path, size: u32) -> Result<Vec<u8>> {
    read_pixels(path, size, |img| img.to_rgb8().into_raw())
}

/// The `size x size` image at `path` as grey bytes.
pub(crate) fn read_gray(path: &Path, size: u32) -> Result<Vec<u8>> {
    read_pixels(path, size, |img| img.to_luma8().into_raw())
}

fn read_pixels(
    path: &Path,
    size: u32,
    pixels: impl FnOnce(image::DynamicImage) -> Vec<u8>,
) -> Result<Vec<u8>> {
    let img = image::open(path).map_err(|e| Error::invalid(path, format!("cannot read: {e}")))?;
    if (img.width(), img.height()) != (size, size) {
        return Err(Error::invalid(
            path,
            format!("is {}x{}, not {size}x{size}", img.width(), img.height()),
        ));
    }
    Ok(pixels(img))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame written and read back stays within 48 dB PSNR of what was written, on a
    /// pattern with a head's range of detail: smooth shading under fine stripes (quality 95
    /// gave about 43 here).
    #[test]
    fn a_frame_survives_its_jpeg() {
        let size = 128u32;
        let rgb: Vec<u8> = (0..size * size)
            .flat_map(|p| {
                let (x, y) = ((p % size) as f32, (p / size) as f32);
                let shade = 90.0 + 0.8 * x + 0.4 * y;
                let fine = 18.0 * (0.9 * x + 0.5 * y).sin() * (0.3 * y).cos();
                [
                    shade + fine,
                    0.7 * shade - fine,
                    200.0 - 0.6 * shade + 0.5 * fine,
                ]
                .map(|v| v.clamp(0.0, 255.0) as u8)
            })
            .collect();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f.jpg");
        save_jpeg(&path, &rgb, size).unwrap();
        let back = read_rgb(&path, size).unwrap();
        let mse = rgb
            .iter()
            .zip(&back)
            .map(|(a, b)| (f64::from(*a) - f64::from(*b)).powi(2))
            .sum::<f64>()
            / rgb.len() as f64;
        let psnr = 10.0 * (255.0f64.powi(2) / mse).log10();
        println!("JPEG at quality {JPEG_QUALITY}: {psnr:.2} dB");
        assert!(psnr >= 48.0, "{psnr:.2} dB");
    }
}
