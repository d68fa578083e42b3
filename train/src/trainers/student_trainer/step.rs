//! A student's training step: the batch's audio codes and per-ray inputs, the forward
//! pass, Eq. 9, the Adam step and the moving average of the weights.

use std::collections::HashMap;

use candle_core::{Device, Tensor};
use nldf_core::beam::encode_beams_parallel;
use nldf_core::metrics::psnr_from_mse;
use nldf_core::rays::Rays;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::batch::BeamRef;
use super::{StudentRun, StudentStep};
use crate::error::{Error, Result};
use crate::networks::nn::sorted_vars;
use crate::trainers::data::TrainData;
use crate::trainers::loss::{RayLosses, TeacherTargets, distillation_loss};
use crate::trainers::pool::PoolEntry;
use crate::trainers::run_loop::finite_loss;

impl StudentRun {
    /// Audio codes of views (each its recorded frame's).
    ///
    /// # Shapes
    /// - returns `[views.len(), audio_dim]`
    fn view_codes(&self, data: &TrainData, views: &[u32]) -> Result<Tensor> {
        let ids: Vec<usize> = views
            .iter()
            .map(|&i| self.views[i as usize].aud_id)
            .collect();
        self.model.audio_codes(data, &ids)
    }
    /// One training step on a main batch and, with the pool on and filled, a pool batch
    /// whose audio codes are detached: the pool trains the light field only.
    pub fn train_step(&mut self, data: &TrainData) -> Result<StudentStep> {
        self.render_pending(data)?;
        let t = self.model.cfg.train.clone();
        let mut rng = ChaCha8Rng::seed_from_u64(t.seed);
        rng.set_stream(self.model.step as u64 + 1);
        let main = self.draw_batch(&mut rng);
        if main.is_empty() {
            return Err(Error::Config(
                "no training pixel's ray hits the head's bounds".into(),
            ));
        }
        let (drawn, pool_refs) = if t.pool {
            let n_pool = (t.hard_ratio.clamp(0.0, 1.0) * t.batch_rays as f64).round() as usize;
            let drawn = self.pool.draw(n_pool, &mut rng);
            let refs = self.pool_refs(&drawn);
            (drawn, refs)
        } else {
            (Vec::new(), Vec::new())
        };
        let jitter_seed = t.jitter.then(|| rng.random::<u64>());
        let out = self.step_on(data, &main, &pool_refs, jitter_seed, true)?;
        let n_main = main.len();
        let candidates: Vec<PoolEntry> = main
            .iter()
            .zip(&out.per_ray[..n_main])
            .map(|(b, &loss)| PoolEntry {
                frame: b.frame,
                pixel: b.pixel,
                loss,
            })
            .collect();
        self.pool.update(&drawn, &out.per_ray[n_main..]);
        let entered = if t.pool {
            self.pool.offer(&candidates, t.hard_ratio)
        } else {
            0
        };
        self.model.step += 1;
        self.update_average()?;
        let step = StudentStep {
            loss: out.loss,
            psnr: psnr_from_mse(out.main_mse),
            entered_pool: entered,
            pool_beams: pool_refs.len(),
        };
        Ok(step)
    }
    /// Trains one batch drawn from the pool alone (the audio encoder gets no gradient).
    /// Returns the batch's loss, or `None` when the pool is empty.
    pub fn pool_step(&mut self, data: &TrainData, n: usize) -> Result<Option<f64>> {
        let mut rng = ChaCha8Rng::seed_from_u64(self.model.cfg.train.seed ^ 0x9e37_79b9);
        rng.set_stream(self.model.step as u64 + 1);
        let drawn = self.pool.draw(n, &mut rng);
        if drawn.is_empty() {
            return Ok(None);
        }
        let refs = self.pool_refs(&drawn);
        let out = self.step_on(data, &[], &refs, None, true)?;
        self.pool.update(&drawn, &out.per_ray);
        Ok(Some(out.loss))
    }

    /// Forward, loss (Eq. 9) and, with `update`, backward and an Adam step over `main` beams
    /// (audio codes with gradients) and `pool` beams (detached codes).
    fn step_on(
        &mut self,
        data: &TrainData,
        main: &[BeamRef],
        pool: &[BeamRef],
        jitter_seed: Option<u64>,
        update: bool,
    ) -> Result<StepOutput> {
        let codes = self.code_table(data, main, pool)?;
        let inputs = self.gather_inputs(data, &codes);
        let RayLosses { per_ray, pixel_sq } =
            self.ray_losses(data, &codes, inputs, jitter_seed, update)?;
        let loss = per_ray.mean_all()?;
        let loss_value = finite_loss(&loss)?;
        if update {
            let lr = self.learning_rate();
            let grads = loss.backward()?;
            self.adam.step(&grads, lr)?;
        }
        let pixel_sq: Vec<f32> = pixel_sq.to_vec1()?;
        let n_main = main.len();
        let main_mse =
            pixel_sq[..n_main].iter().map(|&v| v as f64).sum::<f64>() / (3 * n_main.max(1)) as f64;
        Ok(StepOutput {
            loss: loss_value,
            per_ray: per_ray.to_vec1()?,
            main_mse,
        })
    }

    /// The audio codes of the frames of `main` beams (with gradients) and of `pool` beams
    /// (detached), one row per distinct frame.
    fn code_table(
        &self,
        data: &TrainData,
        main: &[BeamRef],
        pool: &[BeamRef],
    ) -> Result<CodeTable> {
        // Codes: one row per distinct frame, main frames first.
        let mut slot_of: HashMap<(u32, bool), u32> = HashMap::new();
        let (mut main_ids, mut pool_ids) = (Vec::new(), Vec::new());
        let all: Vec<(BeamRef, bool)> = main
            .iter()
            .map(|b| (*b, false))
            .chain(pool.iter().map(|b| (*b, true)))
            .collect();
        for (b, detached) in &all {
            let ids = if *detached {
                &mut pool_ids
            } else {
                &mut main_ids
            };
            if let std::collections::hash_map::Entry::Vacant(e) =
                slot_of.entry((b.frame, *detached))
            {
                e.insert(ids.len() as u32);
                ids.push(b.frame);
            }
        }
        let n_main_frames = main_ids.len() as u32;
        let mut tables = Vec::new();
        if !main_ids.is_empty() {
            tables.push(self.view_codes(data, &main_ids)?);
        }
        if !pool_ids.is_empty() {
            tables.push(self.view_codes(data, &pool_ids)?.detach());
        }
        let table = Tensor::cat(&tables, 0)?;
        Ok(CodeTable {
            all,
            slot_of,
            n_main_frames,
            table,
        })
    }

    /// Each beam's ray, ground-truth pixel, background and teacher targets, gathered from
    /// the cached views, hit pixels and targets.
    fn gather_inputs(&self, data: &TrainData, codes: &CodeTable) -> RayInputs {
        let ds = &data.dataset;
        let distill = self.model.cfg.train.distill;
        let m = self.model.cfg.model.segments;
        let n = codes.all.len();
        let layout = self.target_layout();
        let width = layout.width();
        let floor = self.model.cfg.train.opacity_floor;
        let empty = vec![0.0f32; width];
        let mut inputs = RayInputs {
            rays: Rays::with_capacity(n),
            gt: Vec::with_capacity(3 * n),
            bg: Vec::with_capacity(3 * n),
            tgt: Vec::with_capacity(if distill { 3 * m * n } else { 0 }),
            tgt_alpha: Vec::with_capacity(if distill { n } else { 0 }),
            row_of_ray: Vec::with_capacity(n),
        };
        for (b, detached) in &codes.all {
            let fi = b.frame as usize;
            let view = &self.views[fi];
            let (i, j) = self.beams[fi].pixels[b.pixel as usize];
            let (o, d) = view.camera.ray(i as f32, j as f32);
            inputs.rays.push(o, d);
            // The background is in screen space: a pseudo view's pixel sees the same one.
            let back = ds.background.get(i, j);
            inputs.bg.extend_from_slice(&back);
            let target = if distill {
                let p = b.pixel as usize;
                let mut target = &self.targets[fi][width * p..width * (p + 1)];
                if target[3 * m] < floor {
                    // An empty target: no colour, nothing covering the background.
                    target = &empty[..];
                }
                inputs.tgt.extend_from_slice(&target[..3 * m]);
                inputs.tgt_alpha.push(target[3 * m]);
                target
            } else {
                &[]
            };
            if view.recorded {
                inputs.gt.extend_from_slice(&data.images[fi].get(i, j));
            } else {
                inputs
                    .gt
                    .extend_from_slice(&teacher_pixel(&target[..3 * m], target[3 * m], back));
            }
            inputs.row_of_ray.push(codes.row(b, *detached));
        }
        inputs
    }

    /// The student's forward pass over the gathered rays and Eq. 9 per ray, mouth rays
    /// weighted by `mouth_weight`, with the pixels' squared errors.
    fn ray_losses(
        &self,
        data: &TrainData,
        codes: &CodeTable,
        inputs: RayInputs,
        jitter_seed: Option<u64>,
        update: bool,
    ) -> Result<RayLosses> {
        let ds = &data.dataset;
        let t = &self.model.cfg.train;
        let m = self.model.cfg.model.segments;
        let distill = t.distill;
        let n = codes.all.len();
        let dev = Device::Cpu;
        let row_of_ray = Tensor::from_vec(inputs.row_of_ray, n, &dev)?;
        let code_rows = codes.table.index_select(&row_of_ray, 0)?;
        let spec = &self.model.cfg.model.beam;
        let beams = encode_beams_parallel(&inputs.rays, ds.near, ds.far, spec, jitter_seed);
        let beams = Tensor::from_vec(beams, (n, spec.encoded_len()), &dev)?;
        let out = self
            .model
            .student
            .mlp
            .forward_fused(&beams, &code_rows, update)?;
        let pixels = out.pixels(&Tensor::from_vec(inputs.bg, (n, 3), &dev)?)?;
        let gt = Tensor::from_vec(inputs.gt, (n, 3), &dev)?;
        let tgt = if distill {
            Some((
                Tensor::from_vec(inputs.tgt, (n, m, 3), &dev)?,
                Tensor::from_vec(inputs.tgt_alpha, (n, 1), &dev)?,
            ))
        } else {
            None
        };
        let RayLosses { per_ray, pixel_sq } = distillation_loss(
            &pixels,
            &gt,
            &out.segments,
            &out.logit,
            tgt.as_ref()
                .map(|(segments, opacity)| TeacherTargets { segments, opacity }),
            t.lambda,
        )?;
        // Mouth rays weigh `mouth_weight` times another ray in the loss (and the pool).
        let per_ray = if t.mouth_weight != 1.0 {
            let w = self.mouth_weights(&codes.all);
            (per_ray * Tensor::from_vec(w, n, &dev)?)?
        } else {
            per_ray
        };
        Ok(RayLosses { per_ray, pixel_sq })
    }

    /// Each beam's weight in the loss: `mouth_weight` on a mouth pixel, 1 elsewhere.
    fn mouth_weights(&self, all: &[(BeamRef, bool)]) -> Vec<f32> {
        let t = &self.model.cfg.train;
        all.iter()
            .map(|(b, _)| {
                let mouth = &self.beams[b.frame as usize].mouth;
                if mouth.binary_search(&b.pixel).is_ok() {
                    t.mouth_weight
                } else {
                    1.0
                }
            })
            .collect()
    }

    /// Folds this step's weights into the moving average once the learning rate decays
    /// (`ema_decay` > 0), and on the run's last step puts the average in the weights'
    /// place: `w_avg <- d w_avg + (1 - d) w`, started at the weights themselves.
    fn update_average(&mut self) -> Result<()> {
        let (decay, hold, iters) = {
            let t = &self.model.cfg.train;
            (t.ema_decay, t.lr_hold_steps, t.iters)
        };
        if decay <= 0.0 || self.model.step <= hold {
            return Ok(());
        }
        let vars = sorted_vars(&self.model.varmap)?;
        let average = match self.average.take() {
            None => vars
                .iter()
                .map(|(_, v)| v.as_tensor().copy())
                .collect::<candle_core::Result<Vec<_>>>()?,
            Some(avg) => avg
                .iter()
                .zip(&vars)
                .map(|(a, (_, v))| (a * decay)? + (v.as_tensor() * (1.0 - decay))?)
                .collect::<candle_core::Result<Vec<_>>>()?,
        };
        if self.model.step == iters {
            for (a, (_, v)) in average.iter().zip(&vars) {
                v.set(a)?;
            }
        }
        self.average = Some(average);
        Ok(())
    }
}

/// What a step's forward gives.
struct StepOutput {
    loss: f64,
    /// Eq. 9 per ray (main beams first, then pool beams).
    per_ray: Vec<f32>,
    /// Pixel MSE of the main beams.
    main_mse: f64,
}

/// A step's beams and the table of their audio codes: one row per distinct frame, main
/// frames first, the pool frames' rows detached.
struct CodeTable {
    /// The beams, main beams first, each with whether its code is detached (pool).
    all: Vec<(BeamRef, bool)>,
    /// The row of a (frame, detached) pair within its part of the table.
    slot_of: HashMap<(u32, bool), u32>,
    /// Rows of main frames, before the pool frames' rows.
    n_main_frames: u32,
    /// `[n_main_frames + pool frames, audio_dim]`.
    table: Tensor,
}

impl CodeTable {
    /// The table row of beam `b`'s audio code.
    fn row(&self, b: &BeamRef, detached: bool) -> u32 {
        let slot = self.slot_of[&(b.frame, detached)];
        if detached {
            self.n_main_frames + slot
        } else {
            slot
        }
    }
}

/// A step's per-ray inputs, in the order of [`CodeTable::all`].
struct RayInputs {
    rays: Rays,
    /// Ground-truth pixels, `3 n`.
    gt: Vec<f32>,
    /// Background pixels, `3 n`.
    bg: Vec<f32>,
    /// Teacher segment colours, `3 m n` (distillation only).
    tgt: Vec<f32>,
    /// Teacher opacities, `n` (distillation only).
    tgt_alpha: Vec<f32>,
    /// The code-table row of each ray.
    row_of_ray: Vec<u32>,
}

/// A pseudo view's pixel, which has no image: the teacher's (Eq. 7), the sum of its
/// segment colours, over `back` where it has opacity `alpha`.
fn teacher_pixel(segments: &[f32], alpha: f32, back: [f32; 3]) -> [f32; 3] {
    let mut pixel = [0.0f32; 3];
    for seg in segments.chunks_exact(3) {
        for (p, v) in pixel.iter_mut().zip(seg) {
            *p += v;
        }
    }
    let clear = 1.0 - alpha;
    for (p, b) in pixel.iter_mut().zip(back) {
        *p += clear * b;
    }
    pixel
}
