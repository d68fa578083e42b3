//! `nldf prepare`'s video decoding against known frames: a lossless H.264 clip made from
//! smooth colour ramps decodes back to them without a colour bias.

use nldf_core::image::ImageRgb;
use nldf_prepare::video::{Window, decode_frames, probe};

use crate::util::venv_ffmpeg;

/// Frame `k` of the clip: red across, green down, blue against both, moving with `k`.
fn ramp(size: u32, k: u32) -> ImageRgb {
    let mut img = ImageRgb::filled(size, size, [0.0; 3]);
    let s = (size - 1) as f32;
    for j in 0..size {
        for i in 0..size {
            let (x, y) = (i as f32 / s, j as f32 / s);
            let t = k as f32 * 0.02;
            img.set(
                i,
                j,
                [
                    0.15 + 0.6 * x + t,
                    0.25 + 0.5 * y,
                    0.85 - 0.35 * (x + y) - t,
                ],
            );
        }
    }
    img
}

/// swscale's default YUV-to-RGB path darkened every channel by 1-1.5 levels of 255; the
/// decoder's `accurate_rnd` and full chroma interpolation keep the mean within half a level.
#[test]
fn a_lossless_clip_decodes_to_its_frames_without_a_colour_bias() {
    let Some(ffmpeg) = venv_ffmpeg() else { return };
    let dir = tempfile::tempdir().unwrap();
    let (size, n) = (64u32, 8u32);
    let frames: Vec<ImageRgb> = (0..n).map(|k| ramp(size, k)).collect();
    for (k, f) in frames.iter().enumerate() {
        f.save_png(&dir.path().join(format!("{k}.png"))).unwrap();
    }
    let clip = dir.path().join("ramps.mp4");
    let made = std::process::Command::new(&ffmpeg)
        .args([
            "-nostdin",
            "-y",
            "-loglevel",
            "error",
            "-framerate",
            "25",
            "-i",
        ])
        .arg(dir.path().join("%d.png"))
        .args(["-c:v", "libx264", "-qp", "0", "-pix_fmt", "yuv420p"])
        .arg(&clip)
        .status()
        .unwrap();
    assert!(made.success(), "ffmpeg could not encode the clip");
    let window = Window {
        start: 0.0,
        seconds: None,
        crop: [0, 0, size],
        size,
        fps: None,
    };
    let probed = probe(&ffmpeg, &clip).unwrap();
    let (mut sum, mut sq, mut count) = ([0f64; 3], 0f64, 0f64);
    let decoded = decode_frames(&ffmpeg, &clip, &probed, &window, |k, rgb| {
        let want = frames[k].to_rgb8();
        for (p, (a, b)) in rgb.iter().zip(&want).enumerate() {
            let d = f64::from(*a) - f64::from(*b);
            sum[p % 3] += d;
            sq += d * d;
        }
        count += want.len() as f64 / 3.0;
        Ok(())
    })
    .unwrap();
    assert_eq!(decoded, n as usize);
    let bias = sum.map(|s| s / count);
    let rms = (sq / (3.0 * count)).sqrt();
    println!("mean difference per channel {bias:.3?} levels, rms {rms:.3}");
    assert!(
        bias.iter().all(|b| b.abs() < 0.5),
        "colour bias {bias:?} levels"
    );
    assert!(rms < 2.0, "rms {rms} levels");
}
