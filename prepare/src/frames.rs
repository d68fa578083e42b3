//! The dataset's image files: the JPEG writer and the readers that check a frame's size.

use std::path::Path;

use crate::error::{Error, Result};

/// Writes `rgb` (`size x size`, RGB bytes) as a JPEG at quality 95.
pub(crate) fn save_jpeg(path: &Path, rgb: &[u8], size: u32) -> Result<()> {
    let file = std::fs::File::create(path).map_err(|e| Error::io(path, e))?;
    let mut w = std::io::BufWriter::new(file);
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut w, 95)
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
