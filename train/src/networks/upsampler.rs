//! The learned upsampler (after MobileR2L): the student evaluates one ray per `r x r` block
//! of output pixels, on the coarse grid of
//! [`nldf_core::upsampler_config::coarse_intrinsics`], and a small CNN turns the grid's
//! features into the full-size image on the head's bounding box
//! ([`nldf_core::upsampler_config::coarse_box`]); every pixel outside the box is the
//! background. The network's shape is [`UpsamplerConfig`]'s; this file holds the candle
//! layers and the reference renderer that the exported graph must match.

use candle_core::{D, DType, Device, Module, Result, Tensor};
use candle_nn::{Conv2d, Conv2dConfig, Init, VarBuilder};
use nldf_core::beam::encode_beams_parallel;
use nldf_core::bounds::{Bounds, HeadRange};
use nldf_core::camera::Camera;
use nldf_core::image::ImageRgb;
use nldf_core::rays::{PixelRays, head_rays};
pub use nldf_core::upsampler_config::UpsamplerConfig;
use nldf_core::upsampler_config::{
    Conv2dLayer, MISS_LOGIT, bilinear_kernel, coarse_box, coarse_intrinsics,
};

use crate::networks::student::Student;

/// Rays per student pass when rendering a coarse grid.
const GRID_CHUNK: usize = 8192;

/// The CNN: `reduce` (1x1), `stages.{s}` (3x3, then depth-to-space x2), `head` (3x3).
/// These are the checkpoint's tensor names, which the exporter reads.
#[derive(Debug, Clone)]
pub struct Upsampler {
    pub cfg: UpsamplerConfig,
    /// Width of the student's hidden layer, the input's feature channels (4 more follow:
    /// the colour and the opacity logit).
    pub width: usize,
    reduce: Conv2d,
    stages: Vec<Conv2d>,
    head: Conv2d,
}

/// A convolution of `k x k` kernels, zero-padded by `k / 2`, weights and bias zero until
/// [`init_upsampler_seeded`] or a checkpoint sets them.
fn conv(c_in: usize, c_out: usize, k: usize, vb: VarBuilder) -> Result<Conv2d> {
    let weight = vb.get_with_hints((c_out, c_in, k, k), "weight", Init::Const(0.0))?;
    let bias = vb.get_with_hints(c_out, "bias", Init::Const(0.0))?;
    let cfg = Conv2dConfig {
        padding: k / 2,
        ..Conv2dConfig::default()
    };
    Ok(Conv2d::new(weight, Some(bias), cfg))
}

/// Builds an [`Upsampler`] for `cfg` over a student whose hidden layer is `width` wide, its
/// weights zero (training draws them with [`init_upsampler_seeded`]).
pub fn upsampler(cfg: &UpsamplerConfig, width: usize, vb: VarBuilder) -> Result<Upsampler> {
    let layout = cfg.layout(width);
    let layer = |l: &Conv2dLayer| conv(l.c_in, l.c_out, l.kernel, vb.pp(&l.name));
    let reduce = layer(&layout.reduce)?;
    let stages = layout
        .stages
        .iter()
        .map(layer)
        .collect::<Result<Vec<_>>>()?;
    let head = layer(&layout.head)?;
    Ok(Upsampler {
        cfg: cfg.clone(),
        width,
        reduce,
        stages,
        head,
    })
}

/// Sets the upsampler's weights in `varmap` to seeded values, in name order: every
/// convolution's weights uniform in `±1 / sqrt(fan_in)` (PyTorch's default for a
/// convolution), except the head's, which stay zero (the network starts as bilinear
/// upsampling), as do the biases. Training starts from it, so a run's seed fixes its result.
pub fn init_upsampler_seeded(varmap: &candle_nn::VarMap, seed: u64) -> Result<()> {
    use rand::SeedableRng;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    for (name, var) in crate::networks::nn::sorted_vars(varmap)? {
        if !name.ends_with(".weight") || name.starts_with("head.") {
            continue;
        }
        let fan_in: usize = var.dims().iter().skip(1).product();
        crate::networks::nn::set_uniform(&var, fan_in, &mut rng)?;
    }
    Ok(())
}

/// ONNX's DepthToSpace in its default DCR order: output channel `c` at offset `(i, j)` of
/// each `r x r` block comes from input channel `(i r + j) C + c`.
///
/// # Shapes
/// - `x`: `[n, r r c, h, w]`; returns `[n, c, h r, w r]`
pub fn depth_to_space(x: &Tensor, r: usize) -> Result<Tensor> {
    let (n, rrc, h, w) = x.dims4()?;
    let c = rrc / (r * r);
    x.reshape(vec![n, r, r, c, h, w])?
        .permute(vec![0, 3, 4, 1, 5, 2])?
        .reshape((n, c, h * r, w * r))
}

/// Bilinear upsampling by `r` of each channel, as the transposed convolution of
/// [`bilinear_kernel`] (zero beyond the edges): output pixel `x` interpolates the inputs at
/// `(x + 0.5) / r - 0.5`.
///
/// # Shapes
/// - `x`: `[n, c, h, w]`; returns `[n, c, h r, w r]`
pub fn bilinear_up(x: &Tensor, r: usize) -> Result<Tensor> {
    let c = x.dim(1)?;
    let w = Tensor::from_vec(bilinear_kernel(c, r), (c, c, 2 * r, 2 * r), x.device())?;
    x.conv_transpose2d(&w, r / 2, 0, r, 1)
}

impl Upsampler {
    /// The full-size colour (premultiplied) and opacity logit of a coarse box: the bilinearly
    /// upsampled colour and logit plus the CNN's corrections, the colour's times the upsampled
    /// opacity.
    ///
    /// # Shapes
    /// - `grid`: `[n, width + 4, h, w]`: the hidden layer, then colour and logit
    /// - returns `[n, 4, h r, w r]`
    pub fn forward(&self, grid: &Tensor) -> Result<Tensor> {
        let base = grid.narrow(1, self.width, 4)?;
        let mut x = self.reduce.forward(grid)?.relu()?;
        for stage in &self.stages {
            x = depth_to_space(&stage.forward(&x)?, 2)?.relu()?;
        }
        let up = bilinear_up(&base, self.cfg.factor)?;
        let head = self.head.forward(&x)?;
        // The colour's correction is gated by the upsampled opacity: where the student
        // sees no head, the CNN cannot paint over the background.
        let up_logit = up.narrow(1, 3, 1)?;
        let gate = candle_nn::ops::sigmoid(&up_logit)?;
        let colour = (up.narrow(1, 0, 3)? + head.narrow(1, 0, 3)?.broadcast_mul(&gate)?)?;
        let logit = (up_logit + head.narrow(1, 3, 1)?)?;
        Tensor::cat(&[colour, logit], 1)
    }

    /// The pixels of [`Upsampler::forward`]'s output over `background`: `c + (1 -
    /// sigmoid(logit)) background`.
    ///
    /// # Shapes
    /// - `out`: `[n, 4, H, W]`; `background`: `[n, 3, H, W]`; returns `[n, 3, H, W]`
    pub fn composite(out: &Tensor, background: &Tensor) -> Result<Tensor> {
        let colour = out.narrow(1, 0, 3)?;
        let alpha = candle_nn::ops::sigmoid(&out.narrow(1, 3, 1)?)?;
        colour + alpha.affine(-1.0, 1.0)?.broadcast_mul(background)?
    }
}

/// The student's features on a coarse grid's box.
#[derive(Debug, Clone)]
pub struct CoarseBox {
    /// The box in coarse rays, `(row0, row1, col0, col1)`, ends excluded.
    pub rows: (usize, usize),
    pub cols: (usize, usize),
    /// Whether any coarse ray meets the head's bounds.
    pub any_hit: bool,
    /// Coarse rays evaluated by the student.
    pub n_rays: usize,
    /// `[1, width + 4, rows, cols]`: hidden layer, colour, logit; a miss is zeros and
    /// [`MISS_LOGIT`].
    pub grid: Tensor,
}

/// The student's hidden layer, colour and logit on the coarse grid of `camera` (the output
/// camera) for the upsampler of `factor` and `margin`, on the box around the coarse rays
/// that meet the head; the other rays are not evaluated.
///
/// # Shapes
/// - `code`: `[1, audio_dim]`
pub fn coarse_box_features(
    student: &Student,
    camera: &Camera,
    code: &Tensor,
    range: &HeadRange,
    (factor, margin): (usize, usize),
) -> crate::Result<CoarseBox> {
    let k = coarse_intrinsics(&camera.intrinsics, factor)?;
    let coarse = Camera {
        intrinsics: k,
        c2w: camera.c2w,
    };
    let (hc, wc) = (k.height as usize, k.width as usize);
    let head = head_rays(&coarse, range);
    let mut hits = vec![false; hc * wc];
    for &p in &head.pixels {
        hits[p] = true;
    }
    let (r0, r1, c0, c1) = coarse_box(&hits, wc, margin);
    let (bh, bw) = (r1 - r0, c1 - c0);
    let width = student.cfg.width;
    let channels = width + 4;
    // Channel-last canvas of the box, one row of `channels` per coarse ray.
    let mut canvas = vec![0.0f32; bh * bw * channels];
    for p in 0..bh * bw {
        canvas[p * channels + width + 3] = MISS_LOGIT;
    }
    for (c, chunk) in head.pixels.chunks(GRID_CHUNK).enumerate() {
        let lo = c * GRID_CHUNK;
        let sub = head.rays.slice(lo..lo + chunk.len());
        let (hidden, out) = student_on_rays(student, &sub, range, code)?;
        let row = Tensor::cat(&[&hidden, &out.colour, &out.logit], D::Minus1)?;
        let row: Vec<Vec<f32>> = row.to_vec2()?;
        for (&p, values) in chunk.iter().zip(row) {
            let (j, i) = (p / wc - r0, p % wc - c0);
            let at = (j * bw + i) * channels;
            canvas[at..at + channels].copy_from_slice(&values);
        }
    }
    let grid = Tensor::from_vec(canvas, (1, bh, bw, channels), &Device::Cpu)?
        .permute((0, 3, 1, 2))?
        .contiguous()?;
    Ok(CoarseBox {
        rows: (r0, r1),
        cols: (c0, c1),
        any_hit: !head.pixels.is_empty(),
        n_rays: head.pixels.len(),
        grid,
    })
}

/// The student's last hidden layer `[n, width]` and outputs for the rays `rays`, their
/// beams encoded within the head range's `[near, far]`, all with the audio code `code`
/// (`[1, audio_dim]`).
fn student_on_rays(
    student: &Student,
    rays: &nldf_core::rays::Rays,
    range: &HeadRange,
    code: &Tensor,
) -> Result<(Tensor, crate::networks::student::LightOut)> {
    let spec = &student.cfg.beam;
    let n = rays.len();
    let beams = encode_beams_parallel(rays, range.near, range.far, spec, None);
    let beams = Tensor::from_vec(beams, (n, spec.encoded_len()), &Device::Cpu)?;
    let codes = code.broadcast_as((n, code.dim(1)?))?.contiguous()?;
    student.mlp.forward_hidden(&beams, &codes)
}

/// `[1, 3, h, w]` of the image's pixels in rows `rows` and columns `cols`.
pub fn image_box(image: &ImageRgb, rows: (usize, usize), cols: (usize, usize)) -> Result<Tensor> {
    let w = image.width as usize;
    let (bh, bw) = (rows.1 - rows.0, cols.1 - cols.0);
    let mut out = Vec::with_capacity(3 * bh * bw);
    for c in 0..3 {
        for j in rows.0..rows.1 {
            for i in cols.0..cols.1 {
                out.push(image.data[3 * (j * w + i) + c]);
            }
        }
    }
    Tensor::from_vec(out, (1, 3, bh, bw), &Device::Cpu)
}

/// Renders the frame seen by `camera` with one audio code: the student on the coarse grid's
/// box, the upsampler on it, composited over `background`; every pixel outside the box (and
/// the whole frame when no coarse ray meets the head) is the background. With a mouth patch
/// ([`UpsamplerConfig::mouth_patch`]) the pixels whose rays meet the mouth's box are then
/// the student's own rays over the background ([`paint_mouth_patch`]). Returns the image
/// and the rays the student evaluated, coarse and patch.
///
/// # Shapes
/// - `code`: `[1, audio_dim]`; `background` is the camera's image size
pub fn render_upsampled(
    student: &Student,
    up: &Upsampler,
    camera: &Camera,
    background: &ImageRgb,
    code: &Tensor,
    range: &HeadRange,
) -> crate::Result<(ImageRgb, usize)> {
    let r = up.cfg.factor;
    let coarse = coarse_box_features(student, camera, code, range, (r, up.cfg.margin))?;
    let mut image = background.clone();
    if coarse.any_hit {
        let rows = (coarse.rows.0 * r, coarse.rows.1 * r);
        let cols = (coarse.cols.0 * r, coarse.cols.1 * r);
        let bg = image_box(background, rows, cols)?;
        let out = up.forward(&coarse.grid)?;
        let pixels = Upsampler::composite(&out, &bg)?.squeeze(0)?;
        let pixels: Vec<Vec<Vec<f32>>> = pixels.to_dtype(DType::F32)?.to_vec3()?;
        let w = image.width as usize;
        for (c, plane) in pixels.iter().enumerate() {
            for (y, line) in plane.iter().enumerate() {
                for (x, &v) in line.iter().enumerate() {
                    image.data[3 * ((rows.0 + y) * w + cols.0 + x) + c] = v;
                }
            }
        }
    }
    let patched = match &up.cfg.mouth_patch {
        Some(mouth) => {
            paint_mouth_patch(student, mouth, camera, background, code, range, &mut image)?
        }
        None => 0,
    };
    Ok((image, coarse.n_rays + patched))
}

/// The output pixels of `camera` whose rays meet the mouth's box `mouth` within the head
/// range's `[near, far]`, row by row, with their rays: the mouth patch's rays.
pub fn mouth_patch_rays(camera: &Camera, range: &HeadRange, mouth: &Bounds) -> PixelRays {
    head_rays(
        camera,
        &HeadRange {
            bounds: *mouth,
            ..*range
        },
    )
}

/// Paints the mouth patch into `image`: the student's own rays through the pixels of
/// [`mouth_patch_rays`], composited over `background` (`colour + (1 - opacity)
/// background`). Returns how many rays it evaluated.
///
/// # Shapes
/// - `code`: `[1, audio_dim]`; `image` and `background` are the camera's image size
pub fn paint_mouth_patch(
    student: &Student,
    mouth: &Bounds,
    camera: &Camera,
    background: &ImageRgb,
    code: &Tensor,
    range: &HeadRange,
    image: &mut ImageRgb,
) -> crate::Result<usize> {
    let patch = mouth_patch_rays(camera, range, mouth);
    for (c, chunk) in patch.pixels.chunks(GRID_CHUNK).enumerate() {
        let lo = c * GRID_CHUNK;
        let sub = patch.rays.slice(lo..lo + chunk.len());
        let (_, out) = student_on_rays(student, &sub, range, code)?;
        let bg = Tensor::from_vec(background.gather(chunk), (chunk.len(), 3), &Device::Cpu)?;
        let pixels: Vec<f32> = out.pixels(&bg)?.flatten_all()?.to_vec1()?;
        image.paint(chunk, &pixels);
    }
    Ok(patch.pixels.len())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::networks::nn::new_varmap;

    /// `receptive_halo` is the CNN's reach: changing a coarse cell `halo + 1` cells away
    /// from a pixel's own cell leaves the pixel as it was, changing one `halo` cells away
    /// moves some pixel of the cell (the bound is tight).
    #[test]
    fn the_receptive_halo_is_the_cnns_reach() {
        use nldf_core::upsampler_config::receptive_halo;
        for factor in [2usize, 4, 8] {
            let (varmap, vb) = new_varmap();
            let cfg = UpsamplerConfig::with_factor(factor);
            let width = 6;
            let up = upsampler(&cfg, width, vb).unwrap();
            crate::networks::nn::init_seeded(&varmap, 7 + factor as u64).unwrap();
            let (n, c) = (13usize, width + 4);
            let base: Vec<f32> = (0..c * n * n)
                .map(|i| ((i * 7919 % 1000) as f32 / 500.0 - 1.0) * 0.5)
                .collect();
            let run = |grid: &[f32]| -> Vec<f32> {
                let x = Tensor::from_vec(grid.to_vec(), (1, c, n, n), &Device::Cpu).unwrap();
                up.forward(&x)
                    .unwrap()
                    .flatten_all()
                    .unwrap()
                    .to_vec1()
                    .unwrap()
            };
            let reference = run(&base);
            let halo = receptive_halo(factor);
            // The pixels of the centre cell (6, 6), every output channel.
            let side = n * factor;
            let cell_moved = |out: &[f32]| -> f32 {
                let mut worst = 0f32;
                for ch in 0..4 {
                    for y in 6 * factor..7 * factor {
                        for x in 6 * factor..7 * factor {
                            let at = (ch * side + y) * side + x;
                            worst = worst.max((out[at] - reference[at]).abs());
                        }
                    }
                }
                worst
            };
            let poke = |dy: i64, dx: i64| -> f32 {
                let mut grid = base.clone();
                let (y, x) = ((6 + dy) as usize, (6 + dx) as usize);
                for ch in 0..c {
                    grid[(ch * n + y) * n + x] += 3.0;
                }
                cell_moved(&run(&grid))
            };
            let far = (halo + 1) as i64;
            for (dy, dx) in [(far, 0), (-far, 0), (0, far), (0, -far), (far, far)] {
                assert_eq!(
                    poke(dy, dx),
                    0.0,
                    "x{factor}: a cell at ({dy}, {dx}) reached it"
                );
            }
            let near = halo as i64;
            let reached = [(near, 0), (-near, 0), (0, near), (0, -near)]
                .iter()
                .map(|&(dy, dx)| poke(dy, dx))
                .fold(0f32, f32::max);
            assert!(reached > 1e-4, "x{factor}: no cell {halo} away reached it");
        }
    }

    #[test]
    #[allow(clippy::needless_range_loop)] // indices are the formula under test
    fn depth_to_space_follows_onnx_dcr() {
        // [1, 8, 1, 2] with r = 2, C = 2: out[c, i, 2 x + j] = in[(2 i + j) 2 + c, 0, x].
        let values: Vec<f32> = (0..16).map(|v| v as f32).collect();
        let x = Tensor::from_vec(values, (1, 8, 1, 2), &Device::Cpu).unwrap();
        let y = depth_to_space(&x, 2).unwrap();
        assert_eq!(y.dims(), &[1, 2, 2, 4]);
        let y: Vec<Vec<Vec<f32>>> = y.squeeze(0).unwrap().to_vec3().unwrap();
        for c in 0..2 {
            for i in 0..2 {
                for xx in 0..2 {
                    for j in 0..2 {
                        let channel = (2 * i + j) * 2 + c;
                        assert_eq!(y[c][i][2 * xx + j], (channel * 2 + xx) as f32);
                    }
                }
            }
        }
    }

    #[test]
    #[allow(clippy::needless_range_loop)] // indices are the formula under test
    fn a_fresh_upsampler_upsamples_the_coarse_colour_bilinearly() {
        let cfg = UpsamplerConfig::with_factor(4);
        let (_varmap, vb) = new_varmap();
        let up = upsampler(&cfg, 6, vb).unwrap();
        let grid = Tensor::randn(0f32, 1.0, (1, 10, 3, 5), &Device::Cpu).unwrap();
        let out = up.forward(&grid).unwrap();
        assert_eq!(out.dims(), &[1, 4, 12, 20]);
        let out: Vec<Vec<Vec<f32>>> = out.squeeze(0).unwrap().to_vec3().unwrap();
        let g: Vec<Vec<Vec<f32>>> = grid.squeeze(0).unwrap().to_vec3().unwrap();
        // Inside (every tap on the grid): bilinear between coarse centres.
        for c in 0..4 {
            for y in 2..10 {
                for x in 2..18 {
                    let (u, v) = ((x as f32 + 0.5) / 4.0 - 0.5, (y as f32 + 0.5) / 4.0 - 0.5);
                    let (i0, j0) = (u.floor() as usize, v.floor() as usize);
                    let (tx, ty) = (u - i0 as f32, v - j0 as f32);
                    let at = |i: usize, j: usize| g[6 + c][j][i];
                    let top = at(i0, j0) * (1.0 - tx) + at(i0 + 1, j0) * tx;
                    let bottom = at(i0, j0 + 1) * (1.0 - tx) + at(i0 + 1, j0 + 1) * tx;
                    let want = top * (1.0 - ty) + bottom * ty;
                    assert!((out[c][y][x] - want).abs() < 1e-5, "{c} {y} {x}");
                }
            }
        }
    }
}
