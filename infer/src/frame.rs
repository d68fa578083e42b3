//! One frame from a pose and an audio neighbourhood: rays through every pixel (AD-NeRF's
//! `get_rays` with the model's intrinsics, optionally at another resolution), only the rays
//! that meet the head's bounds within `[near, far]` go through the network, the others take
//! the background pixel, as the student was trained.
//!
//! A model with a learned upsampler (`nldf export --upsampler`) is sent one ray per
//! `r x r` block instead, through the block's centre, again only those that meet the head;
//! the graph upsamples the box around them (widened by the upsampler's margin) and every
//! pixel outside the box is the background, as `nldf_train::upsampler::render_upsampled`
//! renders. With the upsampler's mouth patch, the output pixels whose rays meet the mouth's
//! box go through the student as they are (in the same graph call) and are painted over the
//! upsampled frame.

use glam::Mat4;
use nldf_core::bounds::HeadRange;
use nldf_core::camera::{Camera, Intrinsics};
use nldf_core::image::ImageRgb;
use nldf_core::rays::{PixelRays, all_pixel_rays, box_rays, head_rays};
use nldf_core::upsampler_config::{coarse_box, coarse_intrinsics, receptive_halo};
use nldf_model::contract::{ModelInfo, UpsampleInfo};

use crate::error::{Error, Result};
use crate::runtime::{Backend, BoxInput, PatchRays, RayOutputs};

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
pub struct RenderedFrame {
    /// The image, `[height, width, 3]` in [0, 1].
    pub image: ImageRgb,
    /// Pixels whose rays went through the network (those meeting the head's bounds, unless
    /// skipping is off); with a learned upsampler, the coarse rays that did and the mouth
    /// patch's.
    pub head_pixels: usize,
    /// Of `head_pixels`, the mouth patch's (0 without one).
    pub patch_pixels: usize,
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
    pub fn render(&mut self, c2w: Mat4, audio: &[f32]) -> Result<RenderedFrame> {
        if let Some(up) = self.backend.info().upsample {
            return self.render_upsampled(c2w, audio, up);
        }
        let rays = self.rays(c2w);
        let mut image = self.background.clone();
        let rgb = self.run_rays(&rays, audio)?.rgb;
        image.paint(&rays.pixels, &rgb);
        Ok(RenderedFrame {
            image,
            head_pixels: rays.pixels.len(),
            patch_pixels: 0,
        })
    }

    /// [`FrameRenderer::render`] with a learned upsampler: the coarse rays that meet the
    /// head, the box around them (`coarse_box`, widened by the margin), the graph on the
    /// box, its pixels pasted into the background.
    fn render_upsampled(
        &mut self,
        c2w: Mat4,
        audio: &[f32],
        up: UpsampleInfo,
    ) -> Result<RenderedFrame> {
        let view = self.coarse_view(c2w, up);
        let mut image = self.background.clone();
        let Some(full) = view.full else {
            return Ok(RenderedFrame {
                image,
                head_pixels: 0,
                patch_pixels: 0,
            });
        };
        let patch = self.patch_rays(c2w, up);
        let (rgb, patch_rgb, n_rays) =
            self.run_sub_box(&view, &view.hits, full, &patch, audio, up)?;
        let r = up.factor;
        let w = self.intrinsics.width as usize;
        let (x0, x1) = (full.2 * r, full.3 * r);
        let line = 3 * (x1 - x0);
        for (k, y) in (full.0 * r..full.1 * r).enumerate() {
            image.data[3 * (y * w + x0)..3 * (y * w + x1)]
                .copy_from_slice(&rgb[k * line..(k + 1) * line]);
        }
        image.paint(&patch.pixels, &patch_rgb);
        Ok(RenderedFrame {
            image,
            head_pixels: n_rays + patch.pixels.len(),
            patch_pixels: patch.pixels.len(),
        })
    }

    /// The mouth patch's rays seen from `c2w`: the output pixels whose rays meet the
    /// upsampler's mouth box within `[near, far]` (as `nldf_train`'s `mouth_patch_rays`
    /// finds them); none without a patch.
    fn patch_rays(&self, c2w: Mat4, up: UpsampleInfo) -> PixelRays {
        let Some(mouth) = up.mouth_patch else {
            return PixelRays::default();
        };
        let camera = Camera {
            intrinsics: self.intrinsics,
            c2w,
        };
        let range = HeadRange {
            bounds: mouth,
            ..self.backend.info().spec.head_range()
        };
        box_rays(&camera, &range)
    }

    /// The coarse rays seen from `c2w` that go through the network, their cells and the
    /// box around them.
    fn coarse_view(&self, c2w: Mat4, up: UpsampleInfo) -> CoarseView {
        let rays = self.rays(c2w);
        let wc = self.ray_intrinsics.width as usize;
        let mut hits = vec![false; self.ray_intrinsics.n_pixels()];
        for &p in &rays.pixels {
            hits[p] = true;
        }
        let full = (!rays.pixels.is_empty()).then(|| coarse_box(&hits, wc, up.margin));
        CoarseView { rays, hits, full }
    }

    /// The graph on the sub-box `(row0, row1, col0, col1)` of the coarse grid (within the
    /// view's box), sent the view's rays whose cells `given` (`[hc wc]`) marks (every other
    /// cell a miss) and the mouth patch's rays `patch` (none without a patch): its pixels
    /// `[rows r, cols r, 3]` flat, the patch's `[n_patch, 3]` and the coarse rays sent.
    fn run_sub_box(
        &mut self,
        view: &CoarseView,
        given: &[bool],
        (r0, r1, c0, c1): BoxSides,
        patch: &PixelRays,
        audio: &[f32],
        up: UpsampleInfo,
    ) -> Result<(Vec<f32>, Vec<f32>, usize)> {
        let wc = self.ray_intrinsics.width as usize;
        let send =
            |p: usize| given[p] && (r0..r1).contains(&(p / wc)) && (c0..c1).contains(&(p % wc));
        let cells: Vec<bool> = (r0..r1)
            .flat_map(|j| (c0..c1).map(move |i| j * wc + i))
            .map(|p| view.hits[p] && send(p))
            .collect();
        let (mut origins, mut directions) = (Vec::new(), Vec::new());
        for (k, &p) in view.rays.pixels.iter().enumerate() {
            if send(p) {
                origins.extend_from_slice(&view.rays.rays.origins[3 * k..3 * k + 3]);
                directions.extend_from_slice(&view.rays.rays.directions[3 * k..3 * k + 3]);
            }
        }
        let r = up.factor;
        let w = self.intrinsics.width as usize;
        let (x0, x1) = (c0 * r, c1 * r);
        let background: Vec<f32> = (r0 * r..r1 * r)
            .flat_map(|y| self.background.data[3 * (y * w + x0)..3 * (y * w + x1)].iter())
            .copied()
            .collect();
        let n_rays = origins.len() / 3;
        let patch_background = self.background.gather(&patch.pixels);
        let boxed = BoxInput {
            cells: &cells,
            rows: r1 - r0,
            cols: c1 - c0,
            background: &background,
            patch: up.mouth_patch.map(|_| PatchRays {
                origins: &patch.rays.origins,
                directions: &patch.rays.directions,
                background: &patch_background,
            }),
        };
        let out = self.backend.run_box(&origins, &directions, audio, boxed)?;
        Ok((out.rgb, out.patch_rgb, n_rays))
    }

    /// The pixels (indices into the frame) that the network can change in the frame seen
    /// from `c2w`, as [`PixelRays`]: the pixels whose rays meet the head, with their rays;
    /// with a learned upsampler, every pixel of the head's box, without rays.
    pub fn head_region(&self, c2w: Mat4) -> PixelRays {
        let Some(up) = self.backend.info().upsample else {
            return self.rays(c2w);
        };
        let mut out = PixelRays::default();
        if let Some((r0, r1, c0, c1)) = self.coarse_view(c2w, up).full {
            let (r, w) = (up.factor, self.intrinsics.width as usize);
            for y in r0 * r..r1 * r {
                out.pixels.extend((c0 * r..c1 * r).map(|x| y * w + x));
            }
        }
        out
    }

    /// The colours of the pixels of `region` in the frame seen from `c2w` with the audio
    /// neighbourhood `audio`, as [`FrameRenderer::render`] gives them (within f32
    /// rounding), the rays that went through the network and, of them, the mouth patch's
    /// (as in [`RenderedFrame`]). `region` comes from
    /// [`FrameRenderer::head_region`] (or a subset of it): its rays go through the network;
    /// with a learned upsampler the coarse rays within [`receptive_halo`] cells of the
    /// pixels' own do, and the CNN runs on the part of the head's box around them, which
    /// gives those pixels as the whole box does.
    ///
    /// # Shapes
    /// - returns `rgb` `[region.pixels.len(), 3]` flat
    pub fn render_pixels(
        &mut self,
        c2w: Mat4,
        region: &PixelRays,
        audio: &[f32],
    ) -> Result<(Vec<f32>, usize, usize)> {
        let Some(up) = self.backend.info().upsample else {
            let rgb = self.run_rays(region, audio)?.rgb;
            return Ok((rgb, region.pixels.len(), 0));
        };
        let view = self.coarse_view(c2w, up);
        let (Some(full), false) = (view.full, region.pixels.is_empty()) else {
            return Ok((self.background.gather(&region.pixels), 0, 0));
        };
        let (r, w) = (up.factor, self.intrinsics.width as usize);
        let (hc, wc) = (
            self.ray_intrinsics.height as usize,
            self.ray_intrinsics.width as usize,
        );
        // The cells the pixels read: their own, widened by the halo. Only those rays are
        // sent (the others count as misses, which no wanted pixel reads), and the CNN runs
        // on the box around them.
        let (given, (r0, r1, c0, c1)) = cells_read(&region.pixels, w, r, (hc, wc));
        let sub = (
            r0.max(full.0),
            r1.min(full.1),
            c0.max(full.2),
            c1.min(full.3),
        );
        let patch = patch_within(self.patch_rays(c2w, up), &region.pixels);
        let outside = sub.0 >= sub.1 || sub.2 >= sub.3;
        if outside && patch.rays.pixels.is_empty() {
            // Every pixel lies outside the head's box: the background.
            return Ok((self.background.gather(&region.pixels), 0, 0));
        }
        // Without a hit among the given cells, the whole box (the graph takes one ray at
        // least, and the whole box gives those pixels exactly).
        let any_hit = !outside && (0..hc * wc).any(|p| given[p] && view.hits[p]);
        let (given, sub) = if any_hit {
            (&given, sub)
        } else {
            (&view.hits, full)
        };
        let (rgb, patch_rgb, n_rays) =
            self.run_sub_box(&view, given, sub, &patch.rays, audio, up)?;
        let (y0, y1, x0, x1) = (sub.0 * r, sub.1 * r, sub.2 * r, sub.3 * r);
        let mut out = Vec::with_capacity(3 * region.pixels.len());
        for &p in &region.pixels {
            let (y, x) = (p / w, p % w);
            if (y0..y1).contains(&y) && (x0..x1).contains(&x) {
                let at = 3 * ((y - y0) * (x1 - x0) + x - x0);
                out.extend_from_slice(&rgb[at..at + 3]);
            } else {
                out.extend_from_slice(&self.background.data[3 * p..3 * p + 3]);
            }
        }
        for &(place, k) in &patch.at {
            out[3 * place..3 * place + 3].copy_from_slice(&patch_rgb[3 * k..3 * k + 3]);
        }
        let n_patch = patch.rays.pixels.len();
        Ok((out, n_rays + n_patch, n_patch))
    }

    /// The outputs for `rays` with the audio neighbourhood `audio` (none for no rays),
    /// composited over the renderer's background.
    ///
    /// # Shapes
    /// - `audio`: `[att_frames, window, n_features]` flat
    /// - returns `rgb` `[rays.pixels.len(), 3]` flat (and the segments and opacity)
    pub fn run_rays(&mut self, rays: &PixelRays, audio: &[f32]) -> Result<RayOutputs> {
        if rays.pixels.is_empty() {
            return Ok(RayOutputs::default());
        }
        let background = self.background.gather(&rays.pixels);
        self.backend.run(
            &rays.rays.origins,
            &rays.rays.directions,
            &background,
            audio,
        )
    }
}

/// The mouth patch's rays whose pixels a region lists, and where each of the region's
/// patch pixels takes its colour from.
struct RegionPatch {
    rays: PixelRays,
    /// `(place in the region, ray in rays)` for every region pixel of the patch.
    at: Vec<(usize, usize)>,
}

/// The coarse cells that the output pixels `pixels` (of an image `w` wide, `r` pixels a
/// cell) read through the upsampler: each pixel's own cell widened by
/// [`receptive_halo`] cells, clipped to the `(hc, wc)` grid; and the rectangle of cells
/// holding them, `(row0, row1, col0, col1)` with exclusive ends (`(usize::MAX, 0, ..)` for
/// none).
fn cells_read(
    pixels: &[usize],
    w: usize,
    r: usize,
    (hc, wc): (usize, usize),
) -> (Vec<bool>, (usize, usize, usize, usize)) {
    let halo = receptive_halo(r);
    let mut own = vec![false; hc * wc];
    for &p in pixels {
        own[(p / w / r) * wc + p % w / r] = true;
    }
    let mut given = vec![false; hc * wc];
    let (mut r0, mut r1, mut c0, mut c1) = (usize::MAX, 0, usize::MAX, 0);
    for j in 0..hc {
        for i in 0..wc {
            if !own[j * wc + i] {
                continue;
            }
            let (j0, j1) = (j.saturating_sub(halo), (j + halo + 1).min(hc));
            let (i0, i1) = (i.saturating_sub(halo), (i + halo + 1).min(wc));
            for jj in j0..j1 {
                given[jj * wc + i0..jj * wc + i1].fill(true);
            }
            (r0, r1, c0, c1) = (r0.min(j0), r1.max(j1), c0.min(i0), c1.max(i1));
        }
    }
    (given, (r0, r1, c0, c1))
}

/// The rays of `patch` whose pixels are among `pixels` (each once), with the places of
/// those pixels in `pixels` (a pixel listed twice gets its colour twice).
fn patch_within(patch: PixelRays, pixels: &[usize]) -> RegionPatch {
    let mut out = RegionPatch {
        rays: PixelRays::default(),
        at: Vec::new(),
    };
    if patch.pixels.is_empty() {
        return out;
    }
    let ray_of: std::collections::HashMap<usize, usize> = patch
        .pixels
        .iter()
        .enumerate()
        .map(|(k, &p)| (p, k))
        .collect();
    let mut sent: std::collections::HashMap<usize, usize> = std::collections::HashMap::new();
    for (place, p) in pixels.iter().enumerate() {
        let Some(&k) = ray_of.get(p) else { continue };
        let next = sent.len();
        let ray = *sent.entry(k).or_insert(next);
        if ray == next {
            let rays = &mut out.rays;
            rays.pixels.push(*p);
            rays.rays
                .origins
                .extend_from_slice(&patch.rays.origins[3 * k..3 * k + 3]);
            rays.rays
                .directions
                .extend_from_slice(&patch.rays.directions[3 * k..3 * k + 3]);
        }
        out.at.push((place, ray));
    }
    out
}

/// A box of the coarse grid, `(row0, row1, col0, col1)`, ends excluded.
type BoxSides = (usize, usize, usize, usize);

/// The coarse rays of a frame that go through an upsampled model, their cells (`[hc wc]`)
/// and the box around them (none without rays).
struct CoarseView {
    rays: PixelRays,
    hits: Vec<bool>,
    full: Option<BoxSides>,
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
