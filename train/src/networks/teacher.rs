//! The teacher: audio encoder + field, rendered through the sampler and the compositor.
//! Holds the glue that turns rays, frames and a background into pixel colours.

use candle_core::{Device, Result, Tensor};
use candle_nn::VarBuilder;
use nldf_core::composite::{composite_weights, segment_colors};
use nldf_core::encoding::encoded_len;
use nldf_core::rays::Rays;

use crate::networks::audio_net::{AudioEncoder, audio_encoder};
use crate::networks::field::{TeacherField, teacher_field};
use crate::networks::hash_grid::{HashGrid, hash_grid};
use crate::networks::nn::{Dense, dense};
use crate::networks::occupancy::{OCCUPANCY_VAR, Occupancy, UNMEASURED, sample_occupied};
use crate::networks::render::composite;
use crate::networks::sampler::{RaySamples, sample_importance, sample_stratified};
use crate::networks::teacher_config::TeacherConfig;
use nldf_core::bounds::{Bounds, HeadRange};

/// The audio-conditioned NeRF teacher.
#[derive(Debug, Clone)]
pub struct Teacher {
    pub cfg: TeacherConfig,
    pub audio: AudioEncoder,
    pub field: TeacherField,
    /// The grid teacher's encoding of position (none: frequencies).
    pub grid: Option<HashGrid>,
    /// The grid teacher's region attention: grid features -> one weight per audio channel.
    pub attention: Option<Dense>,
    /// The grid teacher's occupancy grid over the grid's box (none: every sample inside
    /// the bounds).
    pub occupancy: Option<Occupancy>,
}

/// Builds a [`Teacher`] under `vb` (`audio`, `field`, and `grid` for the grid teacher;
/// [`OCCUPANCY_VAR`] with an occupancy grid, which needs the grid's box).
pub fn teacher(cfg: &TeacherConfig, vb: VarBuilder) -> Result<Teacher> {
    let occupancy = match (&cfg.occupancy, &cfg.grid) {
        (Some(o), Some(g)) => {
            let cells = o.resolution.pow(3);
            let (prefix, name) = OCCUPANCY_VAR.split_once('.').unwrap_or(("", OCCUPANCY_VAR));
            let density = vb.pp(prefix).get_with_hints(
                cells,
                name,
                candle_nn::Init::Const(f64::from(UNMEASURED)),
            )?;
            let bounds = Bounds {
                lo: g.lo.into(),
                hi: g.hi.into(),
            };
            Some(Occupancy::new(
                o,
                bounds,
                candle_core::Var::from_tensor(&density)?,
            ))
        }
        (Some(_), None) => {
            return Err(candle_core::Error::Msg(
                "`model.occupancy` needs the grid teacher (`model.grid`)".into(),
            ));
        }
        _ => None,
    };
    Ok(Teacher {
        occupancy,
        cfg: cfg.clone(),
        audio: audio_encoder(&cfg.audio, vb.pp("audio"))?,
        field: teacher_field(cfg, vb.pp("field"))?,
        grid: match &cfg.grid {
            Some(g) => Some(hash_grid(g, vb.pp(GRID_PREFIX))?),
            None => None,
        },
        attention: match &cfg.grid {
            Some(g) if g.region_attention => Some(dense(
                g.dim(),
                cfg.audio.dim,
                true,
                vb.pp("grid_attention"),
            )?),
            _ => None,
        },
    })
}

/// Where the grid teacher's table lies among the teacher's variables.
pub const GRID_PREFIX: &str = "grid";

/// The name of the grid teacher's table among the teacher's variables.
pub const GRID_TABLE: &str = "grid.table";

/// Positional encoding of `n` 3-vectors, in parallel ([`nldf_core::encoding::encode_vectors`]).
///
/// # Shapes
/// - `values`: `[n, 3]` flat; returns `[n, 3 (1 + 2 n_freqs)]`
pub fn encode_vectors(values: &[f32], n_freqs: usize) -> Matrix {
    Matrix {
        data: nldf_core::encoding::encode_vectors(values, n_freqs),
        n: values.len() / 3,
        width: encoded_len(3, n_freqs),
    }
}

/// A flat row-major matrix ready to become a tensor.
#[derive(Debug, Clone, PartialEq)]
pub struct Matrix {
    pub data: Vec<f32>,
    pub n: usize,
    pub width: usize,
}

impl Matrix {
    /// As a `[n, width]` tensor.
    pub fn tensor(self) -> Result<Tensor> {
        Tensor::from_vec(self.data, (self.n, self.width), &Device::Cpu)
    }
}

/// What rendering a batch of rays gives.
#[derive(Debug, Clone)]
pub struct RayColors {
    /// Indices of the rays that hit the head's bounds.
    pub hit: Vec<usize>,
    /// `[n_hit, 3]`: colours of the rays that hit (the others are their background).
    pub color: Tensor,
    /// `[n_hit, n_samples]`: sample weights.
    pub weights: Tensor,
    /// The samples (positions, `t`, spacings).
    pub samples: RaySamples,
}

impl Teacher {
    /// Renders rays: samples inside `bounds`, queries the field with each ray's audio code,
    /// composites over the ray's background. With `rng`, samples are jittered (training).
    ///
    /// # Shapes
    /// - `rays`: `n_rays` rays; `background`: `[n_rays, 3]` flat
    /// - `codes`: `[n_frames, audio_dim]`; `frame_of_ray`: `[n_rays]` indices into `codes`
    #[allow(clippy::too_many_arguments)]
    pub fn render(
        &self,
        rays: &Rays,
        background: &[f32],
        codes: &Tensor,
        frame_of_ray: &[u32],
        bounds: &Bounds,
        near: f32,
        far: f32,
        rng: Option<&mut dyn rand::RngCore>,
    ) -> Result<RayColors> {
        let dev = Device::Cpu;
        let ray_codes = |hit: &[usize]| -> Result<Tensor> {
            let frames: Vec<u32> = hit.iter().map(|&r| frame_of_ray[r]).collect();
            codes.index_select(&Tensor::from_vec(frames, hit.len(), &dev)?, 0)
        };
        let samples = self.sample(rays, bounds, near, far, rng, &|hit| ray_codes(hit))?;
        let n_samples = samples.n_samples;
        let n_hit = samples.hit.len();
        if n_hit == 0 {
            return Ok(RayColors {
                hit: vec![],
                color: Tensor::zeros((0, 3), candle_core::DType::F32, &dev)?,
                weights: Tensor::zeros((0, n_samples), candle_core::DType::F32, &dev)?,
                samples,
            });
        }
        let dirs = encode_vectors(&samples.view_dirs, self.cfg.dir_freqs).tensor()?;
        let ray_codes = ray_codes(&samples.hit)?;
        let (densities, colors) =
            self.query(&samples.points, &ray_codes, &dirs, n_samples, true)?;
        let deltas = Tensor::from_slice(&samples.deltas, (n_hit, n_samples), &dev)?;
        let bg: Vec<f32> = samples
            .hit
            .iter()
            .flat_map(|&r| background[3 * r..3 * r + 3].iter().copied())
            .collect();
        let bg = Tensor::from_vec(bg, (n_hit, 3), &dev)?;
        let out = composite(&densities, &deltas, &colors, &bg)?;
        Ok(RayColors {
            hit: samples.hit.clone(),
            color: out.color,
            weights: out.weights,
            samples,
        })
    }
}

impl Teacher {
    /// The field at `points` (`[n_rays * n_samples, 3]` flat, world units): encoded by the
    /// grid or by frequencies, then densities `[n_rays, n_samples]` and colours
    /// `[n_rays, n_samples, 3]` as [`TeacherField::forward`] gives them. The grid teacher
    /// has no density outside its box. With `train`, gradients flow to every weight.
    ///
    /// # Shapes
    /// - `codes`: `[n_rays, audio_dim]`; `dirs`: `[n_rays, dir_dim]`
    pub fn query(
        &self,
        points: &[f32],
        codes: &Tensor,
        dirs: &Tensor,
        n_samples: usize,
        train: bool,
    ) -> Result<(Tensor, Tensor)> {
        let Some(grid) = &self.grid else {
            let encoded = encode_vectors(points, self.cfg.pos_freqs).tensor()?;
            return self.field.forward(&encoded, codes, dirs, n_samples, train);
        };
        let mut encoded = grid.encode(points, train)?;
        if let Some(att) = &self.attention {
            // a(x) ⊙ code per sample: [n, audio_dim] beside the grid's features.
            let weights = candle_nn::ops::sigmoid(&att.forward(&encoded)?)?;
            let (n, a) = weights.dims2()?;
            let audio = weights
                .reshape((n / n_samples.max(1), n_samples, a))?
                .broadcast_mul(&codes.unsqueeze(1)?)?
                .reshape((n, a))?;
            encoded = Tensor::cat(&[&encoded, &audio], 1)?;
        }
        let (densities, colors) = self
            .field
            .forward(&encoded, codes, dirs, n_samples, train)?;
        let inside = grid.inside(points);
        if inside.iter().all(|&i| i) {
            return Ok((densities, colors));
        }
        let mask: Vec<f32> = inside.iter().map(|&i| f32::from(u8::from(i))).collect();
        let mask = Tensor::from_vec(mask, densities.shape(), densities.device())?;
        Ok(((densities * mask)?, colors))
    }

    /// The samples of each ray that hits `bounds`: `n_samples` stratified ones (over the
    /// occupied cells only, with an occupancy grid: [`sample_occupied`]), plus
    /// `n_importance` drawn from the weights that a coarse pass of the field (no gradient)
    /// gives them. `codes_of` gives the audio codes of a list of hit rays.
    pub fn sample(
        &self,
        rays: &Rays,
        bounds: &Bounds,
        near: f32,
        far: f32,
        mut rng: Option<&mut dyn rand::RngCore>,
        codes_of: &dyn Fn(&[usize]) -> Result<Tensor>,
    ) -> Result<RaySamples> {
        let coarse = match &self.occupancy {
            Some(occ) => sample_occupied(
                rays,
                bounds,
                near,
                far,
                self.cfg.n_samples,
                &occ.mask()?,
                rng.as_deref_mut(),
            ),
            None => sample_stratified(
                rays,
                bounds,
                near,
                far,
                self.cfg.n_samples,
                rng.as_deref_mut(),
            ),
        };
        if self.cfg.n_importance == 0 || coarse.hit.is_empty() {
            return Ok(coarse);
        }
        let weights = self.coarse_weights(&coarse, &codes_of(&coarse.hit)?.detach())?;
        Ok(sample_importance(
            rays,
            &coarse,
            &weights,
            self.cfg.n_importance,
            rng,
        ))
    }

    /// Compositing weights of every sample (forward only, in chunks of rays).
    ///
    /// # Shapes
    /// - `codes`: `[n_hit, audio_dim]`; returns `[n_hit, n_samples]` flat
    pub fn coarse_weights(&self, samples: &RaySamples, codes: &Tensor) -> Result<Vec<f32>> {
        let s = samples.n_samples;
        let mut weights = vec![0.0f32; samples.hit.len() * s];
        self.query_chunks(
            samples,
            &|lo, hi| codes.narrow(0, lo, hi - lo),
            &mut |lo, densities, _| {
                for (k, d) in densities.chunks_exact(s).enumerate() {
                    let h = lo + k;
                    composite_weights(
                        d,
                        &samples.deltas[h * s..(h + 1) * s],
                        &mut weights[h * s..(h + 1) * s],
                    );
                }
                Ok(())
            },
        )?;
        Ok(weights)
    }

    /// Evaluates the field (forward only) on every sample of `samples`, `EVAL_CHUNK` rays at
    /// a time, and hands each chunk's densities `[rays, n_samples]` and colours
    /// `[rays, n_samples, 3]` (flat) to `visit` with the chunk's first ray. `codes_of(lo, hi)`
    /// gives the audio codes of hit rays `lo..hi`.
    fn query_chunks(
        &self,
        samples: &RaySamples,
        codes_of: &dyn Fn(usize, usize) -> Result<Tensor>,
        visit: &mut ChunkVisitor,
    ) -> Result<()> {
        let s = samples.n_samples;
        let n_hit = samples.hit.len();
        let dirs_all = encode_vectors(&samples.view_dirs, self.cfg.dir_freqs);
        for lo in (0..n_hit).step_by(EVAL_CHUNK) {
            let hi = (lo + EVAL_CHUNK).min(n_hit);
            let dirs = Tensor::from_slice(
                &dirs_all.data[lo * dirs_all.width..hi * dirs_all.width],
                (hi - lo, dirs_all.width),
                &Device::Cpu,
            )?;
            let (densities, colors) = self.query(
                &samples.points[3 * s * lo..3 * s * hi],
                &codes_of(lo, hi)?,
                &dirs,
                s,
                false,
            )?;
            let densities: Vec<f32> = densities.flatten_all()?.to_vec1()?;
            let colors: Vec<f32> = colors.flatten_all()?.to_vec1()?;
            visit(lo, &densities, &colors)?;
        }
        Ok(())
    }
}

impl Teacher {
    /// One update of the occupancy grid ([`Occupancy::absorb`]), if the teacher has one:
    /// the field's density at a fresh point in every cell (drawn from `rng`), cell `i` under
    /// row `(i + step) mod n` of `codes` (`[n, audio_dim]`, the batch's codes).
    pub fn update_occupancy(
        &self,
        codes: &Tensor,
        step: usize,
        rng: &mut dyn rand::RngCore,
    ) -> Result<()> {
        let Some(occ) = &self.occupancy else {
            return Ok(());
        };
        let points = occ.cell_points(rng);
        let n_cells = points.len() / 3;
        let n_codes = codes.dim(0)?.max(1);
        let dir = encode_vectors(&[0.0, 0.0, 1.0], self.cfg.dir_freqs);
        let mut sigma = Vec::with_capacity(n_cells);
        for lo in (0..n_cells).step_by(OCCUPANCY_CHUNK) {
            let hi = (lo + OCCUPANCY_CHUNK).min(n_cells);
            let rows: Vec<u32> = (lo..hi).map(|i| ((i + step) % n_codes) as u32).collect();
            let rows = Tensor::from_vec(rows, hi - lo, &Device::Cpu)?;
            let dirs = Tensor::from_slice(&dir.data, (1, dir.width), &Device::Cpu)?
                .broadcast_as((hi - lo, dir.width))?
                .contiguous()?;
            let (density, _) = self.query(
                &points[3 * lo..3 * hi],
                &codes.detach().index_select(&rows, 0)?,
                &dirs,
                1,
                false,
            )?;
            sigma.extend(density.flatten_all()?.to_vec1::<f32>()?);
        }
        occ.absorb(&sigma)
    }
}

/// Cells whose density one call of the field measures in an occupancy update.
const OCCUPANCY_CHUNK: usize = 32_768;

impl Teacher {
    /// Every hit ray of `samples` under one audio `code` (`[1, audio_dim]`), with its
    /// compositing weights (Eq. 3-4): `visit(h, weights, densities, colours)` for hit ray
    /// `h`, its `[n_samples]` weights, densities and `[n_samples, 3]` colours.
    fn visit_weights(
        &self,
        samples: &RaySamples,
        code: &Tensor,
        visit: &mut RayVisitor,
    ) -> Result<()> {
        let s = samples.n_samples;
        let code_rows = |lo: usize, hi: usize| -> Result<Tensor> {
            code.broadcast_as((hi - lo, code.dim(1)?))?.contiguous()
        };
        let mut weights = vec![0.0f32; s];
        self.query_chunks(samples, &code_rows, &mut |lo, densities, colors| {
            for k in 0..densities.len() / s {
                let h = lo + k;
                let densities = &densities[k * s..(k + 1) * s];
                composite_weights(densities, &samples.deltas[h * s..(h + 1) * s], &mut weights);
                visit(h, &weights, densities, &colors[3 * s * k..3 * s * (k + 1)])?;
            }
            Ok(())
        })
    }
}

/// Receives one hit ray's index, weights, densities and colours (flat).
type RayVisitor<'a> = dyn FnMut(usize, &[f32], &[f32], &[f32]) -> Result<()> + 'a;

/// Receives a chunk of field outputs: first hit ray, densities, colours (flat).
type ChunkVisitor<'a> = dyn FnMut(usize, &[f32], &[f32]) -> Result<()> + 'a;

/// Rays rendered together by [`Teacher::render_eval`].
const EVAL_CHUNK: usize = 4096;

impl Teacher {
    /// Samples `rays` inside `range` without jitter, every ray with the audio code `code`
    /// (`[1, audio_dim]`).
    fn sample_with_code(
        &self,
        rays: &Rays,
        range: &HeadRange,
        code: &Tensor,
    ) -> Result<RaySamples> {
        let code_for = |hit: &[usize]| -> Result<Tensor> {
            code.broadcast_as((hit.len(), code.dim(1)?))?.contiguous()
        };
        self.sample(rays, &range.bounds, range.near, range.far, None, &code_for)
    }

    /// Renders rays for display or scoring: no jitter; samples are evaluated front to back in
    /// four groups, and a ray leaves once its transmittance falls below `min_transmittance`
    /// (`cfg.min_transmittance`, or 0 to evaluate every sample); rays that miss the bounds
    /// are their background.
    ///
    /// # Shapes
    /// - `background`: `[n_rays, 3]` flat; `code`: `[1, audio_dim]`
    /// - returns `[n_rays, 3]` flat
    pub fn render_eval(
        &self,
        rays: &Rays,
        background: &[f32],
        code: &Tensor,
        range: &HeadRange,
        min_transmittance: f32,
    ) -> Result<Vec<f32>> {
        let samples = self.sample_with_code(rays, range, code)?;
        let n_samples = samples.n_samples;
        let mut out = background.to_vec();
        let group = n_samples.div_ceil(4);
        let dirs_all = encode_vectors(&samples.view_dirs, self.cfg.dir_freqs);
        for chunk_start in (0..samples.hit.len()).step_by(EVAL_CHUNK) {
            let chunk: Vec<usize> =
                (chunk_start..(chunk_start + EVAL_CHUNK).min(samples.hit.len())).collect();
            let mut color = vec![[0.0f32; 3]; chunk.len()];
            let mut trans = vec![1.0f32; chunk.len()];
            for g0 in (0..n_samples).step_by(group) {
                let g1 = (g0 + group).min(n_samples);
                let g = g1 - g0;
                let active: Vec<usize> = (0..chunk.len())
                    .filter(|&a| trans[a] >= min_transmittance)
                    .collect();
                if active.is_empty() {
                    break;
                }
                let mut points = Vec::with_capacity(active.len() * g * 3);
                let mut dirs = Vec::with_capacity(active.len() * dirs_all.width);
                for &a in &active {
                    let h = chunk[a];
                    points.extend_from_slice(
                        &samples.points[3 * (h * n_samples + g0)..3 * (h * n_samples + g1)],
                    );
                    dirs.extend_from_slice(
                        &dirs_all.data[h * dirs_all.width..(h + 1) * dirs_all.width],
                    );
                }
                let dirs = Tensor::from_vec(dirs, (active.len(), dirs_all.width), &Device::Cpu)?;
                let codes = code
                    .broadcast_as((active.len(), code.dim(1)?))?
                    .contiguous()?;
                let (densities, colors) = self.query(&points, &codes, &dirs, g, false)?;
                let densities: Vec<f32> = densities.flatten_all()?.to_vec1()?;
                let colors: Vec<f32> = colors.flatten_all()?.to_vec1()?;
                for (k, &a) in active.iter().enumerate() {
                    let h = chunk[a];
                    for s in 0..g {
                        let sigma = densities[k * g + s].max(0.0);
                        let tau = (sigma * samples.deltas[h * n_samples + g0 + s])
                            .min(crate::networks::render::MAX_TAU);
                        let w = trans[a] * -(-tau).exp_m1();
                        for c in 0..3 {
                            color[a][c] += w * colors[3 * (k * g + s) + c];
                        }
                        trans[a] *= (-tau).exp();
                    }
                }
            }
            for (a, &h) in chunk.iter().enumerate() {
                let r = samples.hit[h];
                for c in 0..3 {
                    out[3 * r + c] = color[a][c] + trans[a] * background[3 * r + c];
                }
            }
        }
        Ok(out)
    }
}

impl Teacher {
    /// Where each ray meets the head: the point at the teacher's expected depth
    /// `sum_k w_k t_k / sum_k w_k`, for rays whose accumulated weight exceeds one half
    /// (`None` for the others, which mostly see the background). Used to carry a frame's
    /// mouth pixels into views at other poses.
    ///
    /// # Shapes
    /// - `code`: `[1, audio_dim]`; returns one entry per ray
    pub fn surface_points(
        &self,
        rays: &Rays,
        code: &Tensor,
        range: &HeadRange,
    ) -> Result<Vec<Option<glam::Vec3>>> {
        let samples = self.sample_with_code(rays, range, code)?;
        let s = samples.n_samples;
        let mut out = vec![None; rays.len()];
        self.visit_weights(&samples, code, &mut |h, weights, _, _| {
            let acc: f32 = weights.iter().sum();
            if acc > 0.5 {
                let t: f32 = weights
                    .iter()
                    .zip(&samples.t_vals[h * s..(h + 1) * s])
                    .map(|(w, t)| w * t)
                    .sum::<f32>()
                    / acc;
                let r = samples.hit[h];
                out[r] = Some(rays.origin(r) + t * rays.direction(r));
            }
            Ok(())
        })?;
        Ok(out)
    }

    /// The teacher's segment colours of Eq. 5, the student's distillation targets: each
    /// ray's sampled span inside the bounds is cut into `m` equal t-intervals
    /// (`nldf_core::composite::segment_of`, whatever the samples' density, importance
    /// samples included), and segment `i` is the sum of `w_k c_k` over the samples in its
    /// interval with the transmittance accumulated from the ray's start. Each ray's `3 m`
    /// colours are followed by its accumulated weight `sum_k w_k` (how much of the ray the
    /// head covers): the pixel is then `sum_i c_i + (1 - sum_k w_k) background`, the
    /// background staying out of the segments. Rays that miss the bounds are all zeros. No
    /// early termination (measured: evaluating the samples in groups to stop early made the
    /// targets 40 % slower), no jitter.
    ///
    /// # Shapes
    /// - `code`: `[1, audio_dim]`
    /// - returns `[n_rays, 3 m + 1]` flat
    pub fn segment_targets(
        &self,
        rays: &Rays,
        code: &Tensor,
        range: &HeadRange,
        m: usize,
    ) -> Result<Vec<f32>> {
        let m = m.max(1);
        let width = 3 * m + 1;
        let samples = self.sample_with_code(rays, range, code)?;
        let s = samples.n_samples;
        let mut out = vec![0.0f32; rays.len() * width];
        self.visit_weights(&samples, code, &mut |h, weights, densities, colors| {
            let segments = segment_colors(
                weights,
                colors,
                &samples.t_vals[h * s..(h + 1) * s],
                samples.spans[h],
                m,
            );
            let optical_depth: f32 = (0..s)
                .map(|j| {
                    (densities[j].max(0.0) * samples.deltas[h * s + j])
                        .min(crate::networks::render::MAX_TAU)
                })
                .sum();
            let r = samples.hit[h];
            let dst = &mut out[r * width..(r + 1) * width];
            dst[..3 * m].copy_from_slice(&segments);
            // 1 - exp(-x) without cancellation for thin rays.
            dst[3 * m] = -(-optical_depth).exp_m1();
            Ok(())
        })?;
        Ok(out)
    }
}
