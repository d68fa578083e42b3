//! Skipping the pixels the audio does not move. While the head's pose holds still between
//! frames, most rays give the same colour whatever the audio: only the mouth, the jaw and
//! the cheeks change. The model itself says which: at a still pose every head ray is
//! rendered with a few probe audio neighbourhoods (frames spread over the clip), and a
//! pixel whose colour spreads over them (and the last full frame) by more than a threshold
//! in any channel, grown by a margin of pixels, is re-rendered every frame; every other
//! pixel keeps the last full frame's colour.
//!
//! A full frame is rendered whenever the pose moves (by any amount) and every `refresh`
//! frames at a still pose; the pixel set is found once per still pose, on its second frame,
//! at the cost of one network pass per probe.
//!
//! With a learned upsampler the pixels are the head's box's, and a frame re-renders the
//! part of the box within reach of the moving pixels
//! ([`FrameRenderer::render_pixels`]): the coarse rays there and the CNN on that part.

use glam::Mat4;
use nldf_core::image::ImageRgb;
use nldf_core::rays::{PixelRays, Rays};
use serde::Serialize;

use crate::error::{Error, Result};
use crate::frame::{FrameRenderer, RenderedFrame};

/// The default [`SkipConfig::threshold`] in steps of 1/255 of a colour channel, the unit
/// the command line's `--skip-threshold` takes.
pub const DEFAULT_THRESHOLD_STEPS: f32 = 12.0;

/// Settings of [`StillSkipper`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SkipConfig {
    /// A pixel is re-rendered when its colour spread over the probes (and the last full
    /// frame) exceeds this, in colour units of [0, 1] (default
    /// [`DEFAULT_THRESHOLD_STEPS`] / 255, 12/255). It bounds a kept pixel's error for the
    /// probes' audio only: a sound between the probes can move a kept pixel further
    /// (`nldf bench still` measures by how much).
    pub threshold: f32,
    /// Pixels within this many pixels (a square) of one over the threshold are re-rendered
    /// too (default 2).
    pub margin: u32,
    /// A full frame every this many frames at a still pose (default 25: once a second).
    pub refresh: usize,
    /// Probe audio neighbourhoods (default 8).
    pub probes: usize,
}

impl Default for SkipConfig {
    fn default() -> Self {
        SkipConfig {
            threshold: DEFAULT_THRESHOLD_STEPS / 255.0,
            margin: 2,
            refresh: 25,
            probes: 8,
        }
    }
}

impl SkipConfig {
    /// Checks the settings.
    pub fn validate(&self) -> Result<()> {
        if !(self.threshold.is_finite() && self.threshold >= 0.0) {
            return Err(Error::Argument(format!(
                "skip threshold must be finite and >= 0, got {}",
                self.threshold
            )));
        }
        if self.refresh == 0 || self.probes == 0 || self.margin > 64 {
            return Err(Error::Argument(format!(
                "skipping needs refresh >= 1, probes >= 1 and margin <= 64, got {}, {} and {}",
                self.refresh, self.probes, self.margin
            )));
        }
        Ok(())
    }
}

/// The video frames whose audio neighbourhoods probe the model: `k` of `n_frames`, evenly
/// spread (the middle of each of `k` equal stretches).
pub fn probe_frames(n_frames: usize, k: usize) -> Vec<usize> {
    let k = k.min(n_frames);
    (0..k)
        .map(|i| (((2 * i + 1) * n_frames) / (2 * k)).min(n_frames.saturating_sub(1)))
        .collect()
}

/// How a frame of [`StillSkipper::render`] was made.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum FrameKind {
    /// Every head ray went through the network.
    Full,
    /// The pixel set was found at this pose (one pass per probe), then only it rendered.
    Probed,
    /// Only the pose's pixel set was rendered.
    Partial,
}

/// A frame of [`StillSkipper::render`].
#[derive(Debug, Clone, PartialEq)]
pub struct SkippedFrame {
    /// The image; `head_pixels` counts the rays this frame's audio went through the
    /// network for (the probes' passes not included).
    pub frame: RenderedFrame,
    pub kind: FrameKind,
}

/// Renders frames, re-rendering only the pixels the audio moves while the pose holds.
#[derive(Debug)]
pub struct StillSkipper {
    config: SkipConfig,
    /// `[att_frames, window, n_features]` flat, each.
    probes: Vec<Vec<f32>>,
    /// The pose of the last full frame and that frame.
    pose: Option<Mat4>,
    base: Option<ImageRgb>,
    /// The rays re-rendered at `pose`, once found.
    moving: Option<PixelRays>,
    since_full: usize,
}

impl StillSkipper {
    /// A skipper probing the model with `probes` (audio neighbourhoods, at least one).
    pub fn new(config: SkipConfig, probes: Vec<Vec<f32>>) -> Result<StillSkipper> {
        config.validate()?;
        if probes.is_empty() {
            return Err(Error::Argument(
                "skipping needs at least one probe audio neighbourhood".into(),
            ));
        }
        Ok(StillSkipper {
            config,
            probes,
            pose: None,
            base: None,
            moving: None,
            since_full: 0,
        })
    }

    /// Re-rendered pixels at the current still pose, once found.
    pub fn moving_pixels(&self) -> Option<usize> {
        self.moving.as_ref().map(|m| m.pixels.len())
    }

    /// The frame seen from `c2w` with the audio neighbourhood `audio`: a full frame when
    /// the pose moved or `refresh` frames have passed, else the last full frame with the
    /// pose's moving pixels re-rendered.
    pub fn render(
        &mut self,
        renderer: &mut FrameRenderer,
        c2w: Mat4,
        audio: &[f32],
    ) -> Result<SkippedFrame> {
        let still = self.pose.is_some_and(|p| p == c2w);
        let base = match &self.base {
            Some(base) if still && self.since_full < self.config.refresh => base.clone(),
            _ => {
                let frame = renderer.render(c2w, audio)?;
                if !still {
                    self.moving = None;
                }
                self.pose = Some(c2w);
                self.base = Some(frame.image.clone());
                self.since_full = 1;
                return Ok(SkippedFrame {
                    frame,
                    kind: FrameKind::Full,
                });
            }
        };
        let (moving, kind) = match self.moving.take() {
            Some(moving) => (moving, FrameKind::Partial),
            None => (self.find_moving(renderer, c2w, &base)?, FrameKind::Probed),
        };
        self.since_full += 1;
        let mut image = base;
        let (rgb, head_pixels, patch_pixels) = renderer.render_pixels(c2w, &moving, audio)?;
        image.paint(&moving.pixels, &rgb);
        self.moving = Some(moving);
        Ok(SkippedFrame {
            frame: RenderedFrame {
                image,
                head_pixels,
                patch_pixels,
            },
            kind,
        })
    }

    /// The head rays at `c2w` whose colour over the probes and `base` spreads by more than
    /// the threshold, grown by the margin.
    fn find_moving(
        &self,
        renderer: &mut FrameRenderer,
        c2w: Mat4,
        base: &ImageRgb,
    ) -> Result<PixelRays> {
        let rays = renderer.head_region(c2w);
        let n = rays.pixels.len();
        let mut lo = vec![f32::INFINITY; 3 * n];
        let mut hi = vec![f32::NEG_INFINITY; 3 * n];
        let mut widen = |rgb: &[f32]| {
            for (k, &v) in rgb.iter().enumerate() {
                lo[k] = lo[k].min(v);
                hi[k] = hi[k].max(v);
            }
        };
        let first: Vec<f32> = rays
            .pixels
            .iter()
            .flat_map(|&p| base.data[3 * p..3 * p + 3].iter().copied())
            .collect();
        widen(&first);
        for probe in &self.probes {
            widen(&renderer.render_pixels(c2w, &rays, probe)?.0);
        }
        let k = renderer.intrinsics();
        let hot: Vec<(u32, u32)> = (0..n)
            .filter(|&r| (0..3).any(|c| hi[3 * r + c] - lo[3 * r + c] > self.config.threshold))
            .map(|r| rays.pixel_ij(r, k.width))
            .collect();
        Ok(grown_subset(
            &rays,
            &hot,
            self.config.margin,
            k.width,
            k.height,
        ))
    }
}

/// The rays of `rays` whose pixels lie within `margin` (a square) of a pixel of `hot`.
fn grown_subset(
    rays: &PixelRays,
    hot: &[(u32, u32)],
    margin: u32,
    width: u32,
    height: u32,
) -> PixelRays {
    let (w, h) = (width as usize, height as usize);
    let mut keep = vec![false; w * h];
    let m = margin as i64;
    for &(i, j) in hot {
        for dj in -m..=m {
            for di in -m..=m {
                let (x, y) = (i as i64 + di, j as i64 + dj);
                if (0..w as i64).contains(&x) && (0..h as i64).contains(&y) {
                    keep[y as usize * w + x as usize] = true;
                }
            }
        }
    }
    let mut out = PixelRays {
        rays: Rays::with_capacity(hot.len()),
        pixels: Vec::with_capacity(hot.len()),
    };
    // A region without rays (a learned upsampler's box) stays without.
    let with_rays = rays.rays.len() == rays.pixels.len();
    for (r, &p) in rays.pixels.iter().enumerate() {
        if keep[p] {
            if with_rays {
                out.rays.push(rays.rays.origin(r), rays.rays.direction(r));
            }
            out.pixels.push(p);
        }
    }
    out
}

/// One pose track of [`bench_still`]: every frame rendered in full and with skipping, one
/// after the other (so a change of machine load hits both).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StillTrack {
    /// What the track is.
    pub label: String,
    pub frames: usize,
    /// Mean and median milliseconds per frame, in full and with skipping (the probed
    /// frame and the full frames included in the mean).
    pub full_ms_mean: f64,
    pub full_ms_median: f64,
    pub skip_ms_mean: f64,
    pub skip_ms_median: f64,
    /// `full_ms_mean / skip_ms_mean`.
    pub speedup: f64,
    /// Frames the skipping rendered in full.
    pub full_frames: usize,
    /// Network rays per frame with skipping, as a share of the full frames' (mean).
    pub ray_share: f64,
    /// PSNR of the skipping's frames against the full renders over all frames (their mean
    /// squared error), and the worst frame's; `None` where they are identical.
    pub psnr_vs_full: Option<f64>,
    pub worst_frame_psnr: Option<f64>,
    /// Largest difference of any channel of any pixel.
    pub max_abs_error: f32,
}

/// PSNR of a mean squared error (colours in [0, 1]); `None` for 0.
fn psnr_of(mse: f64) -> Option<f64> {
    (mse > 0.0).then(|| -10.0 * mse.log10())
}

/// Renders `poses` with the audio neighbourhoods `audio(f)` in full and with skipping
/// (`config`, probes from `probes`), timing each frame and comparing the two.
pub fn bench_track(
    full: &mut FrameRenderer,
    skipping: &mut FrameRenderer,
    label: &str,
    poses: &[Mat4],
    audio: &dyn Fn(usize) -> Vec<f32>,
    config: SkipConfig,
    probes: Vec<Vec<f32>>,
) -> Result<StillTrack> {
    let mut skipper = StillSkipper::new(config, probes)?;
    let (mut full_ms, mut skip_ms) = (Vec::new(), Vec::new());
    let (mut sq_err, mut worst, mut max_abs) = (0.0f64, 0.0f64, 0.0f32);
    let (mut full_rays, mut skip_rays, mut full_frames) = (0usize, 0usize, 0usize);
    let mut values = 0usize;
    for (f, &pose) in poses.iter().enumerate() {
        let a = audio(f);
        let t = std::time::Instant::now();
        let reference = full.render(pose, &a)?;
        full_ms.push(1e3 * t.elapsed().as_secs_f64());
        let t = std::time::Instant::now();
        let out = skipper.render(skipping, pose, &a)?;
        skip_ms.push(1e3 * t.elapsed().as_secs_f64());
        full_rays += reference.head_pixels;
        skip_rays += out.frame.head_pixels;
        full_frames += usize::from(out.kind == FrameKind::Full);
        let mut frame_sq = 0.0f64;
        for (x, y) in out.frame.image.data.iter().zip(&reference.image.data) {
            let d = x - y;
            max_abs = max_abs.max(d.abs());
            frame_sq += (d as f64) * (d as f64);
        }
        let n = reference.image.data.len();
        sq_err += frame_sq;
        values += n;
        worst = worst.max(frame_sq / n.max(1) as f64);
    }
    let frames = poses.len();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let median = nldf_core::stats::median;
    Ok(StillTrack {
        label: label.to_string(),
        frames,
        full_ms_mean: mean(&full_ms),
        full_ms_median: median(&full_ms),
        skip_ms_mean: mean(&skip_ms),
        skip_ms_median: median(&skip_ms),
        speedup: mean(&full_ms) / mean(&skip_ms).max(1e-9),
        full_frames,
        ray_share: skip_rays as f64 / full_rays.max(1) as f64,
        psnr_vs_full: psnr_of(sq_err / values.max(1) as f64),
        worst_frame_psnr: psnr_of(worst),
        max_abs_error: max_abs,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn probes_spread_over_the_clip() {
        assert_eq!(probe_frames(100, 4), vec![12, 37, 62, 87]);
        assert_eq!(probe_frames(3, 8), vec![0, 1, 2]);
        assert!(probe_frames(0, 8).is_empty());
    }

    #[test]
    fn the_margin_grows_the_set_inside_the_head() {
        // A 5 x 5 image whose head rays are the pixels of columns 1..=3.
        let mut rays = PixelRays {
            rays: Rays::with_capacity(15),
            pixels: Vec::new(),
        };
        for j in 0..5u32 {
            for i in 1..=3u32 {
                rays.rays.push(glam::Vec3::ZERO, glam::Vec3::Z);
                rays.pixels.push((j * 5 + i) as usize);
            }
        }
        let none = grown_subset(&rays, &[(2, 2)], 0, 5, 5);
        assert_eq!(none.pixels, vec![12]);
        let one = grown_subset(&rays, &[(0, 0)], 1, 5, 5);
        // (0, 0) is no head ray; its neighbourhood holds head pixels (1, 0) and (1, 1).
        assert_eq!(one.pixels, vec![1, 6]);
        assert_eq!(one.rays.len(), 2);
    }
}
