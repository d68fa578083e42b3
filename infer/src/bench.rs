//! Rendering benchmarks (cargo feature `ort`): what a whole frame costs next to the bare
//! network, how the two runtimes compare, and how frame time follows the number of pixels
//! the head covers.
//!
//! - **ort whole frame against bare onnxruntime**: the same rays, in the same batches,
//!   once as [`FrameRenderer::render`] does it (rays for every pixel, the head test, the
//!   network, copying outputs, assembling the image) and once as bare `Session::run` calls
//!   on ready-made inputs ([`OrtBackend::run_bare`]). The two are timed alternately so that
//!   a change in machine load hits both.
//! - **tract against ort**: whole frames at the same pose.
//! - **frame time against head coverage**: the camera zooms out (a shorter focal length at
//!   the same pose, so the rays keep the trained depth range) until the head covers a given
//!   share of the pixels, and each frame is timed; the reference is the frame with ray
//!   skipping off, where every pixel goes through the network.

use std::time::Instant;

use glam::Mat4;
use nldf_model::ExportedModel;
use serde::Serialize;

use crate::backend::{BackendKind, BackendOptions, backend_for};
use crate::error::{Error, Result};
use crate::frame::FrameRenderer;
use crate::ort_backend::OrtBackend;
use crate::poses::default_pose;

/// Settings of [`bench_render`].
#[derive(Debug, Clone, Serialize)]
pub struct RenderBenchConfig {
    /// Timed repetitions per measurement (the median is reported).
    pub reps: usize,
    /// Untimed repetitions before each measurement.
    pub warmup: usize,
    /// Batch size and threads of both runtimes.
    pub options: BackendOptions,
    /// Head coverages (shares of the pixels) to time frames at.
    pub coverages: Vec<f64>,
}

impl Default for RenderBenchConfig {
    fn default() -> Self {
        RenderBenchConfig {
            reps: 7,
            warmup: 2,
            options: BackendOptions::default(),
            coverages: vec![0.05, 0.1, 0.2, 0.3, 0.45],
        }
    }
}

/// One timed frame.
#[derive(Debug, Clone, Serialize)]
pub struct FrameTiming {
    /// What was timed.
    pub label: String,
    /// Focal length the frame was rendered with, in pixels.
    pub focal: f32,
    /// Rays that went through the network.
    pub network_rays: usize,
    /// Pixels whose rays meet the head's bounds, as a share of the image.
    pub head_fraction: f64,
    /// Median seconds per frame.
    pub seconds: f64,
    /// Network rays per second.
    pub rays_per_s: f64,
}

/// What [`bench_render`] measured.
#[derive(Debug, Clone, Serialize)]
pub struct RenderBench {
    /// Linear layers and width of the network.
    pub depth: usize,
    pub width: usize,
    /// Image size.
    pub image_width: u32,
    pub image_height: u32,
    pub settings: RenderBenchConfig,
    /// Bare `Session::run` calls on the default frame's rays, ready-made.
    pub bare_ort: FrameTiming,
    /// The default frame rendered by the ort backend.
    pub ort_frame: FrameTiming,
    /// Bare seconds / whole-frame seconds (the issue asks for >= 0.8).
    pub ort_frame_over_bare: f64,
    /// The default frame rendered by the tract backend.
    pub tract_frame: FrameTiming,
    /// tract seconds / ort seconds (the issue asks for <= 2).
    pub tract_over_ort: f64,
    /// ort, ray skipping off: every pixel through the network.
    pub full_frame: FrameTiming,
    /// ort frames at each asked head coverage, skipping on.
    pub coverage: Vec<FrameTiming>,
    /// The coverage frame closest to 30 %: its time as a share of `full_frame`'s (the
    /// issue asks for <= 0.4).
    pub at_30_percent: Option<(f64, f64)>,
}

/// Median seconds of `reps` calls of `f` after `warmup` untimed ones.
fn median_seconds(warmup: usize, reps: usize, mut f: impl FnMut() -> Result<()>) -> Result<f64> {
    for _ in 0..warmup {
        f()?;
    }
    let mut times = Vec::with_capacity(reps);
    for _ in 0..reps.max(1) {
        let t = Instant::now();
        f()?;
        times.push(t.elapsed().as_secs_f64());
    }
    Ok(nldf_core::stats::median(&times))
}

/// Sets and returns the focal length at which the head covers about `target` of the pixels
/// seen from `c2w`, found by bisection between `base / 100` and `10 base` (the covered
/// share grows with the focal length).
fn focal_for_coverage(
    renderer: &mut FrameRenderer,
    c2w: Mat4,
    base: f32,
    target: f64,
) -> Result<f32> {
    let n = renderer.intrinsics().n_pixels() as f64;
    let (mut lo, mut hi) = (base * 0.01, base * 10.0);
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        renderer.set_focal(mid)?;
        let share = renderer.rays(c2w).pixels.len() as f64 / n;
        if share < target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let f = 0.5 * (lo + hi);
    renderer.set_focal(f)?;
    Ok(f)
}

/// A timing of `rays` network rays in `seconds` by `r` at the pose `c2w`, with the share of
/// the frame's `n_pixels` that meet the head there.
fn frame_timing(
    label: &str,
    r: &FrameRenderer,
    c2w: Mat4,
    n_pixels: f64,
    seconds: f64,
    rays: usize,
) -> FrameTiming {
    FrameTiming {
        label: label.to_string(),
        focal: r.intrinsics().focal,
        network_rays: rays,
        head_fraction: r.rays(c2w).pixels.len() as f64 / n_pixels,
        seconds,
        rays_per_s: rays as f64 / seconds.max(1e-12),
    }
}

/// The frame timed with the head covering each of `cfg.coverages` of the pixels (the focal
/// that gives it recorded in each timing); `ort`'s own focal is put back after.
fn coverage_runs(
    ort: &mut FrameRenderer,
    c2w: Mat4,
    n_pixels: f64,
    cfg: &RenderBenchConfig,
    audio: &[f32],
    progress: &mut impl FnMut(&str),
) -> Result<Vec<FrameTiming>> {
    let own_focal = ort.intrinsics().focal;
    let mut coverage = Vec::new();
    for &target in &cfg.coverages {
        progress(&format!(
            "ort: head covering {:.0} % of the pixels",
            100.0 * target
        ));
        let focal = focal_for_coverage(ort, c2w, own_focal, target)?;
        let rays = ort.rays(c2w).pixels.len();
        let s = median_seconds(cfg.warmup, cfg.reps, || ort.render(c2w, audio).map(|_| ()))?;
        let mut t = frame_timing(
            &format!("ort, {:.0} % target", 100.0 * target),
            ort,
            c2w,
            n_pixels,
            s,
            rays,
        );
        t.focal = focal;
        coverage.push(t);
    }
    ort.set_focal(own_focal)?;
    Ok(coverage)
}

/// The coverage run whose head share is nearest 30 % (within 5 points): that share and its
/// time over the frame with every pixel through the network (`full_seconds`).
fn near_30_percent(coverage: &[FrameTiming], full_seconds: f64) -> Option<(f64, f64)> {
    coverage
        .iter()
        .min_by(|a, b| {
            (a.head_fraction - 0.3)
                .abs()
                .total_cmp(&(b.head_fraction - 0.3).abs())
        })
        .filter(|t| (t.head_fraction - 0.3).abs() < 0.05)
        .map(|t| (t.head_fraction, t.seconds / full_seconds))
}

/// Times `model`'s frames: see the module documentation.
pub fn bench_render(
    model: &ExportedModel,
    cfg: &RenderBenchConfig,
    mut progress: impl FnMut(&str),
) -> Result<RenderBench> {
    if cfg.reps == 0 {
        return Err(Error::Argument("reps must be at least 1".into()));
    }
    let info = &model.info;
    let c2w = default_pose(info, 0);
    // Silence: the network's cost does not depend on the audio.
    let audio = vec![-1.0f32; info.audio.len()];
    let mut bare = OrtBackend::new(model, cfg.options)?;
    let mut ort = FrameRenderer::new(backend_for(model, BackendKind::Ort, cfg.options)?, None)?;
    let mut tract = FrameRenderer::new(backend_for(model, BackendKind::Tract, cfg.options)?, None)?;
    let k = ort.intrinsics();
    let n_pixels = k.n_pixels() as f64;
    let timing = |label: &str, r: &FrameRenderer, seconds: f64, rays: usize| {
        frame_timing(label, r, c2w, n_pixels, seconds, rays)
    };

    progress("ort: whole frames against bare onnxruntime");
    let rays = ort.rays(c2w);
    let n_rays = rays.pixels.len();
    let background =
        crate::frame::background_at(ort.info(), ort.intrinsics().width, ort.intrinsics().height)?
            .gather(&rays.pixels);
    // One block after the other, never alternating: a session that has just run keeps its
    // pool spinning for a while, and two sessions taking turns fight over the cores (on
    // 2 cores that made the bare session look 20-50 % slower than onnxruntime from Python).
    let bare_s = median_seconds(cfg.warmup, cfg.reps, || {
        bare.run_bare(
            &rays.rays.origins,
            &rays.rays.directions,
            &background,
            &audio,
        )
    })?;
    drop(bare);
    let frame_s = median_seconds(cfg.warmup, cfg.reps, || ort.render(c2w, &audio).map(|_| ()))?;
    let bare_ort = timing("bare onnxruntime", &ort, bare_s, n_rays);
    let ort_frame = timing("ort frame", &ort, frame_s, n_rays);

    progress("tract: whole frames");
    let tract_s = median_seconds(cfg.warmup, cfg.reps, || {
        tract.render(c2w, &audio).map(|_| ())
    })?;
    let tract_frame = timing("tract frame", &tract, tract_s, n_rays);
    drop(tract);

    progress("ort: every pixel through the network");
    ort.set_skip_rays(false);
    let full_s = median_seconds(cfg.warmup, cfg.reps, || ort.render(c2w, &audio).map(|_| ()))?;
    let mut full_frame = timing("ort, no ray skipping", &ort, full_s, k.n_pixels());
    full_frame.head_fraction = ort_frame.head_fraction;
    ort.set_skip_rays(true);

    let coverage = coverage_runs(&mut ort, c2w, n_pixels, cfg, &audio, &mut progress)?;
    let at_30_percent = near_30_percent(&coverage, full_frame.seconds);
    Ok(RenderBench {
        depth: info.network.depth,
        width: info.network.width,
        image_width: k.width,
        image_height: k.height,
        settings: cfg.clone(),
        ort_frame_over_bare: bare_ort.seconds / ort_frame.seconds,
        tract_over_ort: tract_frame.seconds / ort_frame.seconds,
        bare_ort,
        ort_frame,
        tract_frame,
        full_frame,
        coverage,
        at_30_percent,
    })
}
