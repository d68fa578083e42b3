//! Image quality metrics on RGB images in [0, 1]: PSNR, SSIM (Wang et al. 2004: Gaussian
//! 11 x 11 window, sigma 1.5, K1 = 0.01, K2 = 0.03, valid filtering, mean over channels) and
//! PSNR inside a region mask (mouth, eyes).

use crate::error::{Error, Result};
use crate::image::ImageRgb;

fn check_same_size(a: &ImageRgb, b: &ImageRgb) -> Result<()> {
    if a.width != b.width || a.height != b.height {
        return Err(Error::Argument(format!(
            "images differ in size: {}x{} against {}x{}",
            a.width, a.height, b.width, b.height
        )));
    }
    Ok(())
}

/// A region mask `[height * width]` of `image`'s pixels.
fn check_mask(image: &ImageRgb, mask: &[bool]) -> Result<()> {
    if mask.len() != image.n_pixels() {
        return Err(Error::Argument(format!(
            "mask has {} entries for an image of {} pixels",
            mask.len(),
            image.n_pixels()
        )));
    }
    Ok(())
}

/// PSNRs are reported up to this many dB: identical images would otherwise score infinity.
pub const PSNR_CAP: f64 = 100.0;

/// `psnr` capped at [`PSNR_CAP`], with a NaN kept as NaN: `f64::min` would turn a NaN into
/// the cap, scoring a broken frame as a perfect one.
pub fn cap_psnr(psnr: f64) -> f64 {
    if psnr.is_nan() {
        psnr
    } else {
        psnr.min(PSNR_CAP)
    }
}

/// PSNR in dB from a mean squared error on a [0, 1] scale: `-10 log10(mse)`;
/// `f64::INFINITY` for identical images (callers print it as `inf`), NaN for a NaN error.
pub fn psnr_from_mse(mse: f64) -> f64 {
    if mse <= 0.0 {
        f64::INFINITY
    } else {
        -10.0 * mse.log10()
    }
}

/// Mean squared error over all pixels and channels.
pub fn mse(a: &ImageRgb, b: &ImageRgb) -> Result<f64> {
    check_same_size(a, b)?;
    let sum: f64 = a
        .data
        .iter()
        .zip(&b.data)
        .map(|(&x, &y)| ((x - y) as f64).powi(2))
        .sum();
    Ok(sum / a.data.len().max(1) as f64)
}

/// PSNR in dB over the whole image (infinite for identical images).
pub fn psnr(a: &ImageRgb, b: &ImageRgb) -> Result<f64> {
    Ok(psnr_from_mse(mse(a, b)?))
}

/// PSNR in dB over the pixels where `mask` is true (`[height * width]`, row-major); `None`
/// when the mask selects no pixel.
pub fn psnr_masked(a: &ImageRgb, b: &ImageRgb, mask: &[bool]) -> Result<Option<f64>> {
    check_same_size(a, b)?;
    check_mask(a, mask)?;
    let (mut sum, mut n) = (0.0f64, 0usize);
    for (p, _) in mask.iter().enumerate().filter(|(_, m)| **m) {
        for c in 0..3 {
            sum += ((a.data[3 * p + c] - b.data[3 * p + c]) as f64).powi(2);
        }
        n += 3;
    }
    Ok((n > 0).then(|| psnr_from_mse(sum / n as f64)))
}

/// The normalised 1-D Gaussian of `size` taps and standard deviation `sigma`.
fn gaussian_kernel(size: usize, sigma: f64) -> Vec<f64> {
    let c = (size as f64 - 1.0) / 2.0;
    let k: Vec<f64> = (0..size)
        .map(|i| (-((i as f64 - c).powi(2)) / (2.0 * sigma * sigma)).exp())
        .collect();
    let s: f64 = k.iter().sum();
    k.into_iter().map(|v| v / s).collect()
}

/// Separable valid filtering of a `w` x `h` plane by `k` along x then y.
fn filter_valid(plane: &[f64], w: usize, h: usize, k: &[f64]) -> (Vec<f64>, usize, usize) {
    let n = k.len();
    let (ow, oh) = (w + 1 - n, h + 1 - n);
    let mut tmp = vec![0.0; ow * h];
    for y in 0..h {
        for x in 0..ow {
            tmp[y * ow + x] = (0..n).map(|t| k[t] * plane[y * w + x + t]).sum();
        }
    }
    let mut out = vec![0.0; ow * oh];
    for y in 0..oh {
        for x in 0..ow {
            out[y * ow + x] = (0..n).map(|t| k[t] * tmp[(y + t) * ow + x]).sum();
        }
    }
    (out, ow, oh)
}

/// Mean SSIM of two images: per channel with a Gaussian window (11 x 11, sigma 1.5; smaller
/// and odd for images under 11 pixels), valid filtering, averaged over channels. 1 for
/// identical images.
pub fn ssim(a: &ImageRgb, b: &ImageRgb) -> Result<f64> {
    Ok(ssim_map(a, b)?.mean())
}

/// [`ssim`] of the whole images and over the windows whose centre pixel `mask` selects
/// (`[height * width]`, row-major; `None` when it selects none, a mask only along the
/// border, say), from one SSIM map.
pub fn ssim_with_mask(a: &ImageRgb, b: &ImageRgb, mask: &[bool]) -> Result<(f64, Option<f64>)> {
    check_mask(a, mask)?;
    let map = ssim_map(a, b)?;
    let w = a.width as usize;
    let (mut sum, mut n) = (0.0, 0usize);
    for y in 0..map.height {
        for x in 0..map.width {
            if mask[(y + map.half) * w + x + map.half] {
                sum += map.values[y * map.width + x];
                n += 1;
            }
        }
    }
    Ok((map.mean(), (n > 0).then(|| sum / n as f64)))
}

/// SSIM per window position (valid filtering), averaged over channels.
struct SsimMap {
    values: Vec<f64>,
    width: usize,
    height: usize,
    /// Offset of a window's centre from its corner.
    half: usize,
}

impl SsimMap {
    /// The mean over every window: the image's SSIM.
    fn mean(&self) -> f64 {
        self.values.iter().sum::<f64>() / self.values.len() as f64
    }
}

fn ssim_map(a: &ImageRgb, b: &ImageRgb) -> Result<SsimMap> {
    check_same_size(a, b)?;
    let (w, h) = (a.width as usize, a.height as usize);
    if w == 0 || h == 0 {
        return Err(Error::Argument("SSIM of an empty image".into()));
    }
    let mut size = 11.min(w).min(h);
    if size % 2 == 0 {
        size -= 1;
    }
    let k = gaussian_kernel(size, 1.5);
    let (c1, c2) = (0.01f64.powi(2), 0.03f64.powi(2));
    let (ow, oh) = (w + 1 - size, h + 1 - size);
    let mut values = vec![0.0; ow * oh];
    for c in 0..3 {
        let x: Vec<f64> = (0..w * h).map(|p| a.data[3 * p + c] as f64).collect();
        let y: Vec<f64> = (0..w * h).map(|p| b.data[3 * p + c] as f64).collect();
        let xx: Vec<f64> = x.iter().map(|v| v * v).collect();
        let yy: Vec<f64> = y.iter().map(|v| v * v).collect();
        let xy: Vec<f64> = x.iter().zip(&y).map(|(u, v)| u * v).collect();
        let (mx, _, _) = filter_valid(&x, w, h, &k);
        let (my, _, _) = filter_valid(&y, w, h, &k);
        let (sxx, _, _) = filter_valid(&xx, w, h, &k);
        let (syy, _, _) = filter_valid(&yy, w, h, &k);
        let (sxy, _, _) = filter_valid(&xy, w, h, &k);
        for (p, v) in values.iter_mut().enumerate() {
            let (mx, my) = (mx[p], my[p]);
            let vx = sxx[p] - mx * mx;
            let vy = syy[p] - my * my;
            let cov = sxy[p] - mx * my;
            *v += ((2.0 * mx * my + c1) * (2.0 * cov + c2))
                / ((mx * mx + my * my + c1) * (vx + vy + c2))
                / 3.0;
        }
    }
    Ok(SsimMap {
        values,
        width: ow,
        height: oh,
        half: size / 2,
    })
}
