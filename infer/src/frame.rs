//! One frame from a pose and an audio neighbourhood: rays through every pixel (AD-NeRF's
//! `get_rays` with the model's intrinsics, optionally at another resolution), only the rays
//! that meet the head's bounds within `[near, far]` go through the network, the others take
//! the background pixel, as the student was trained.
//!
//! A model with a learned upsampler (`nldf export --upsampler`) is sent one ray per
//! `r x r` block instead, through the block's centre, again only those that meet the head;
//! the graph upsamples the box around them (widened by the upsampler's margin) and every
//! pixel outside the box is the background, as `nldf_train::upsampler::render_upsampled`
//! renders.

use glam::Mat4;
use nldf_core::camera::{Camera, Intrinsics};
use nldf_core::image::ImageRgb;
use nldf_core::rays::{PixelRays, all_pixel_rays, head_rays};
use nldf_core::upsampler_shape::{coarse_box, coarse_intrinsics};
use nldf_export::contract::{ModelInfo, UpsampleInfo};

use crate::error::{Error, Result};
use crate::runtime::{Backend, BoxInput, RayOutputs};

/// Largest image side `nldf render` accepts.
pub const MAX_SIDE: u32 = 8192;

/// The model's intrinsics at an image whose longer side is `size` pixels (the aspect ratio
/// kept, focal and principal point scaled), or unchanged for `None`.
pub fn intrinsics_at(info: &ModelInfo, size: Option<u32>) -> Result<Intrinsics> {
    let k = info.spec.intrinsics;
    let Some(size) = size else { return Ok(k) };
    if size == 0 || size > MAX_SIDE {
        return Err(Error::Argument(format!(
            "image size must be 1 to {MAX_SIDE} pixels, got {size}"
        )));
    }
    let long = k.width.max(k.height) as f64;
    let scale = |v: u32| ((v as f64 * size as f64 / long).round() as u32).max(1);
    Ok(k.resized(scale(k.width), scale(k.height)))
}

/// The background of the model's metadata, at `width` x `height` (bilinear when resized).
pub fn background_at(info: &ModelInfo, width: u32, height: u32) -> Result<ImageRgb> {
    let bad = |e: String| Error::Argument(format!("the model's background image: {e}"));
    let img = image::load_from_memory(&info.background_png)
        .map_err(|e| bad(e.to_string()))?
        .to_rgb8();
    let img = if img.dimensions() == (width, height) {
        img
    } else {
        image::imageops::resize(&img, width, height, image::imageops::FilterType::Triangle)
    };
    Ok(ImageRgb::from_rgb8(width, height, img.as_raw()))
}

/// A rendered frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// The image, `[height, width, 3]` in [0, 1].
    pub image: ImageRgb,
    /// Pixels whose rays went through the network (those meeting the head's bounds, unless
    /// skipping is off); with a learned upsampler, the coarse rays that did.
    pub head_pixels: usize,
}

/// Renders frames of one model with one backend.
pub struct FrameRenderer {
    backend: Box<dyn Backend>,
    intrinsics: Intrinsics,
    /// The rays' intrinsics: `intrinsics`, or the upsampler's coarse grid of them.
    ray_intrinsics: Intrinsics,
    background: ImageRgb,
    /// Send only the rays that meet the head's bounds through the network.
    skip_rays: bool,
}

impl std::fmt::Debug for FrameRenderer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FrameRenderer")
            .field("backend", &self.backend.kind())
            .field("batch_size", &self.backend.batch_size())
            .field("intrinsics", &self.intrinsics)
            .finish()
    }
}

impl FrameRenderer {
    /// A renderer at the model's own size (`size` `None`) or with the longer side `size`.
    pub fn new(backend: Box<dyn Backend>, size: Option<u32>) -> Result<FrameRenderer> {
        let intrinsics = intrinsics_at(backend.info(), size)?;
        Self::with_intrinsics(backend, intrinsics)
    }

    /// A renderer of frames seen with `intrinsics`, the background resized to them.
    fn with_intrinsics(backend: Box<dyn Backend>, intrinsics: Intrinsics) -> Result<FrameRenderer> {
        let background = background_at(backend.info(), intrinsics.width, intrinsics.height)?;
        let ray_intrinsics = rays_seen(backend.info(), &intrinsics)?;
        Ok(FrameRenderer {
            backend,
            intrinsics,
            ray_intrinsics,
            background,
            skip_rays: true,
        })
    }

    /// A renderer of frames `factor` times smaller than `size` (the longer side), to be
    /// upscaled bilinearly by `factor`: one ray through the centre of each `factor x factor`
    /// block of the `size` frame ([`coarse_intrinsics`]), so that the upscaled frame lines up
    /// with the full-size one. (The model's intrinsics scaled by `1 / factor` would put each
    /// ray at its block's corner instead, shifting the upscaled frame by `(factor - 1) / 2`
    /// pixels.)
    pub fn for_upscaling(
        backend: Box<dyn Backend>,
        size: u32,
        factor: u32,
    ) -> Result<FrameRenderer> {
        if let Some(up) = backend.info().upsample {
            return Err(Error::Argument(format!(
                "this model has a learned upsampler (x{}): it renders full-size frames itself",
                up.factor
            )));
        }
        let full = intrinsics_at(backend.info(), Some(size))?;
        let intrinsics = coarse_intrinsics(&full, factor.max(1) as usize)
            .map_err(|e| Error::Argument(e.to_string()))?;
        Self::with_intrinsics(backend, intrinsics)
    }

    /// The model's metadata.
    pub fn info(&self) -> &ModelInfo {
        self.backend.info()
    }

    /// The intrinsics frames are rendered with.
    pub fn intrinsics(&self) -> Intrinsics {
        self.intrinsics
    }

    /// The backend, e.g. for its kind.
    pub fn backend(&self) -> &dyn Backend {
        self.backend.as_ref()
    }

    /// Sets the focal length in pixels (the image size stays): a smaller focal length
    /// zooms out, so the head covers fewer pixels at the same camera pose and depth range.
    pub fn set_focal(&mut self, focal: f32) -> Result<()> {
        if !(focal.is_finite() && focal > 0.0) {
            return Err(Error::Argument(format!(
                "focal length must be positive, got {focal}"
            )));
        }
        self.intrinsics.focal = focal;
        self.ray_intrinsics = rays_seen(self.backend.info(), &self.intrinsics)?;
        Ok(())
    }

    /// Whether rays that miss the head's bounds skip the network (the default) or every
    /// pixel goes through it (to measure what the skipping saves).
    pub fn set_skip_rays(&mut self, skip: bool) {
        self.skip_rays = skip;
    }

    /// The rays of the frame seen from camera-to-world `c2w` that go through the network:
    /// those meeting the head's bounds within `[near, far]` ([`head_rays`], the rays the
    /// student was trained on), or all with skipping off. With a learned upsampler they are
    /// the coarse grid's, and their pixels index it.
    pub fn rays(&self, c2w: Mat4) -> PixelRays {
        let camera = Camera {
            intrinsics: self.ray_intrinsics,
            c2w,
        };
        let spec = &self.backend.info().spec;
        if self.skip_rays {
            head_rays(&camera, &spec.head_range())
        } else {
            all_pixel_rays(&camera)
        }
    }

    /// The frame seen from camera-to-world `c2w` with the audio neighbourhood `audio`.
    ///
    /// # Shapes
    /// - `audio`: `[att_frames, window, n_features]` flat
    /// - returns an image of the renderer's [`FrameRenderer::intrinsics`] size
    pub fn render(&mut self, c2w: Mat4, audio: &[f32]) -> Result<Frame> {
        if let Some(up) = self.backend.info().upsample {
            return self.render_upsampled(c2w, audio, up);
        }
        let rays = self.rays(c2w);
        let mut image = self.background.clone();
        let rgb = self.run_rays(&rays, audio)?.rgb;
        image.paint(&rays.pixels, &rgb);
        Ok(Frame {
            image,
            head_pixels: rays.pixels.len(),
        })
    }

    /// [`FrameRenderer::render`] with a learned upsampler: the coarse rays that meet the
    /// head, the box around them (`coarse_box`, widened by the margin), the graph on the
    /// box, its pixels pasted into the background.
    fn render_upsampled(&mut self, c2w: Mat4, audio: &[f32], up: UpsampleInfo) -> Result<Frame> {
        let rays = self.rays(c2w);
        let mut image = self.background.clone();
        if rays.pixels.is_empty() {
            return Ok(Frame {
                image,
                head_pixels: 0,
            });
        }
        let (hc, wc) = (
            self.ray_intrinsics.height as usize,
            self.ray_intrinsics.width as usize,
        );
        let mut hits = vec![false; hc * wc];
        for &p in &rays.pixels {
            hits[p] = true;
        }
        let (r0, r1, c0, c1) = coarse_box(&hits, wc, up.margin);
        let cells: Vec<bool> = (r0..r1)
            .flat_map(|j| hits[j * wc + c0..j * wc + c1].iter().copied())
            .collect();
        let r = up.factor;
        let w = self.intrinsics.width as usize;
        let (x0, x1) = (c0 * r, c1 * r);
        let background: Vec<f32> = (r0 * r..r1 * r)
            .flat_map(|y| self.background.data[3 * (y * w + x0)..3 * (y * w + x1)].iter())
            .copied()
            .collect();
        let boxed = BoxInput {
            cells: &cells,
            rows: r1 - r0,
            cols: c1 - c0,
            background: &background,
        };
        let out = self
            .backend
            .run_box(&rays.rays.origins, &rays.rays.directions, audio, boxed)?;
        let line = 3 * (x1 - x0);
        for (k, y) in (r0 * r..r1 * r).enumerate() {
            image.data[3 * (y * w + x0)..3 * (y * w + x1)]
                .copy_from_slice(&out.rgb[k * line..(k + 1) * line]);
        }
        Ok(Frame {
            image,
            head_pixels: rays.pixels.len(),
        })
    }

    /// The outputs for `rays` with the audio neighbourhood `audio` (none for no rays),
    /// composited over the renderer's background for a model with opacity.
    ///
    /// # Shapes
    /// - `audio`: `[att_frames, window, n_features]` flat
    /// - returns `rgb` `[rays.pixels.len(), 3]` flat (and the segments and opacity)
    pub fn run_rays(&mut self, rays: &PixelRays, audio: &[f32]) -> Result<RayOutputs> {
        if rays.pixels.is_empty() {
            return Ok(RayOutputs::default());
        }
        let background = if self.backend.info().opacity {
            self.background.gather(&rays.pixels)
        } else {
            Vec::new()
        };
        self.backend.run(
            &rays.rays.origins,
            &rays.rays.directions,
            &background,
            audio,
        )
    }
}

/// The intrinsics of the rays a model is sent for frames of `intrinsics`: those, or with a
/// learned upsampler its coarse grid's ([`coarse_intrinsics`]; the frame's sides must be
/// multiples of the factor).
fn rays_seen(info: &ModelInfo, intrinsics: &Intrinsics) -> Result<Intrinsics> {
    match info.upsample {
        None => Ok(*intrinsics),
        Some(up) => coarse_intrinsics(intrinsics, up.factor)
            .map_err(|e| Error::Argument(format!("the model's learned upsampler: {e}"))),
    }
}
