//! PSNR and SSIM on known cases.

use nldf_core::image::ImageRgb;
use nldf_core::metrics::{psnr, psnr_masked, ssim};
use nldf_tests::pattern_image;

#[test]
fn identical_images_give_ssim_one_and_infinite_psnr() {
    let a = pattern_image(40, 30, 3);
    let p = psnr(&a, &a).unwrap();
    assert!(p.is_infinite() && p > 0.0);
    assert!((ssim(&a, &a).unwrap() - 1.0).abs() < 1e-12);
    let mask = vec![true; 1200];
    assert!(psnr_masked(&a, &a, &mask).unwrap().unwrap().is_infinite());
    // Infinite PSNR formats without panicking.
    assert_eq!(format!("{p:.2}"), "inf");
}

#[test]
fn psnr_of_a_constant_offset() {
    // MSE of a uniform offset of 0.1 is 0.01: PSNR = 20 dB exactly.
    let a = ImageRgb::filled(8, 8, [0.3, 0.5, 0.7]);
    let b = ImageRgb::filled(8, 8, [0.4, 0.6, 0.8]);
    assert!((psnr(&a, &b).unwrap() - 20.0).abs() < 1e-4);
}

#[test]
fn masked_psnr_sees_only_the_mask() {
    let a = ImageRgb::filled(4, 4, [0.5; 3]);
    let mut b = a.clone();
    b.set(0, 0, [0.0; 3]);
    let mut mask = vec![false; 16];
    mask[15] = true;
    assert!(psnr_masked(&a, &b, &mask).unwrap().unwrap().is_infinite());
    mask[0] = true;
    // Two masked pixels, one off by 0.5 in all channels: MSE 0.125.
    let want = -10.0 * 0.125f64.log10();
    assert!((psnr_masked(&a, &b, &mask).unwrap().unwrap() - want).abs() < 1e-6);
    assert!(psnr_masked(&a, &b, &[false; 16]).unwrap().is_none());
    assert!(psnr_masked(&a, &b, &[true; 3]).is_err());
}

#[test]
fn ssim_of_constant_images_follows_the_luminance_term() {
    // With zero variance SSIM is (2 m1 m2 + C1) / (m1^2 + m2^2 + C1).
    let a = ImageRgb::filled(16, 16, [0.2; 3]);
    let b = ImageRgb::filled(16, 16, [0.6; 3]);
    let c1 = 0.0001;
    let want = (2.0 * 0.2 * 0.6 + c1) / (0.04 + 0.36 + c1);
    let got = ssim(&a, &b).unwrap();
    assert!((got - want).abs() < 1e-6, "{got} vs {want}");
}

#[test]
fn ssim_drops_with_noise_and_sizes_must_match() {
    let a = pattern_image(32, 32, 1);
    let mut b = a.clone();
    for (k, v) in b.data.iter_mut().enumerate() {
        *v = (*v + if k % 2 == 0 { 0.08 } else { -0.08 }).clamp(0.0, 1.0);
    }
    let s = ssim(&a, &b).unwrap();
    assert!(s < 0.99 && s > 0.0, "{s}");
    assert!(ssim(&a, &pattern_image(16, 32, 1)).is_err());
    assert!(psnr(&a, &pattern_image(16, 32, 1)).is_err());
}

/// The repainted share counts the pixels outside the head that differ from the background
/// by more than 1.5/255 in any channel (a NaN counts), and never a head pixel.
#[test]
fn the_repainted_share_counts_changed_background_pixels_outside_the_head() {
    use nldf_core::region::Region;
    use nldf_train::reports::eval::{REPAINT_THRESHOLD, repainted_share};
    let bg = ImageRgb::filled(4, 4, [0.5, 0.25, 0.75]);
    let mut regions = vec![Region::Background; 16];
    for p in [5, 6, 9, 10] {
        regions[p] = Region::Face;
    }
    let mut render = bg.clone();
    assert_eq!(repainted_share(&render, &bg, &regions), Some(0.0));
    // Head pixels may change freely.
    render.data[3 * 5] = 0.0;
    assert_eq!(repainted_share(&render, &bg, &regions), Some(0.0));
    // Just under the threshold is kept; just over is repainted.
    render.data[0] += 0.9 * REPAINT_THRESHOLD;
    assert_eq!(repainted_share(&render, &bg, &regions), Some(0.0));
    render.data[3 + 1] += 1.1 * REPAINT_THRESHOLD;
    render.data[3 * 15 + 2] = f32::NAN;
    assert_eq!(repainted_share(&render, &bg, &regions), Some(2.0 / 12.0));
    // A frame that is all head has no background to repaint.
    assert_eq!(repainted_share(&render, &bg, &[Region::Face; 16]), None);
}
