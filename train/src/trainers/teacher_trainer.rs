//! The teacher's trainer: AD-NeRF's recipe (face-biased ray batches, Adam with exponential
//! learning-rate decay, AudioAttNet switched on late at a higher rate) with periodic
//! validation, `log.csv`, atomic checkpoints and bit-exact resume.
//!
//! Every step draws its batch from a generator seeded by `(seed, step)`, so a resumed run
//! sees exactly the batches an uninterrupted one would have seen.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use candle_core::{Device, Tensor};
use candle_nn::VarMap;
use nldf_core::dataset::{Frame, Split};
use nldf_core::image::ImageRgb;
use nldf_core::metrics::psnr_from_mse;
use nldf_core::rays::{Rays, rays_for_image, sample_batch};
use rand::seq::index::sample as sample_indices;
use rand::{Rng, RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::error::{Error, Result};
use crate::networks::nn::{new_varmap, scaled_vars};
use crate::networks::occupancy::OCCUPANCY_VAR;
use crate::networks::teacher::{Teacher, teacher};
use crate::trainers::adam::{Adam, AdamParams};
use crate::trainers::checkpoint::save_json;
use crate::trainers::checkpoint::{CheckpointParts, Clock, open_checkpoint, save_checkpoint};
use crate::trainers::config::{RunConfig, TeacherRunConfig, read_config};
use crate::trainers::data::TrainData;
use crate::trainers::run_loop::{Event, TrainingRun, finite_loss, run_fields, train_loop};
use crate::trainers::scores::{Scores, score_validation_frames};
use glam::Vec3;
use nldf_core::bounds::Bounds;
use nldf_core::run_files::CONFIG_FILE;

/// Half the side of the box that stands for "no bounds" when a frame is rendered without
/// skipping: far beyond any scene's cameras, so every ray's samples span `[near, far]`.
const NO_SKIP_REACH: f32 = 1e4;

/// A trained teacher, for rendering: its folder, configuration and weights, and the step
/// they were saved at. [`TeacherModel::open`] reads nothing of the training state (the
/// optimizer's moments), so a model renders whether or not its run can resume.
pub struct TeacherModel {
    pub dir: PathBuf,
    pub cfg: TeacherRunConfig,
    pub varmap: VarMap,
    pub teacher: Teacher,
    /// Steps done.
    pub step: usize,
    /// Training seconds the checkpoint it was opened from records, across resumes (0 for
    /// a new model; a run's own clock is its `elapsed()`).
    pub trained_s: f64,
}

impl TeacherModel {
    /// Loads the trained teacher in `dir`: its `config.json` and weights.
    pub fn open(dir: &Path) -> Result<TeacherModel> {
        let mut model = Self::build(dir, read_config(&dir.join(CONFIG_FILE))?)?;
        let (step, clock) = open_checkpoint(dir, &model.varmap, None)?;
        (model.step, model.trained_s) = (step, clock.elapsed());
        Ok(model)
    }

    /// The network of `cfg` at step 0, weights as the variable builder made them.
    fn build(dir: &Path, cfg: TeacherRunConfig) -> Result<TeacherModel> {
        cfg.check()?;
        let (varmap, vb) = new_varmap();
        let teacher = teacher(&cfg.model, vb)?;
        Ok(TeacherModel {
            dir: dir.to_path_buf(),
            cfg,
            varmap,
            teacher,
            step: 0,
            trained_s: 0.0,
        })
    }

    fn attention_on(&self) -> bool {
        self.step >= self.cfg.train.att_start
    }

    /// Audio codes of `frames` (indices into the dataset's audio windows).
    ///
    /// # Shapes
    /// - returns `[frames.len(), audio_dim]`
    pub fn audio_codes(&self, data: &TrainData, aud_ids: &[usize]) -> Result<Tensor> {
        let windows = data.neighbourhoods(aud_ids, self.cfg.model.audio.att_frames)?;
        Ok(self.teacher.audio.forward(&windows, self.attention_on())?)
    }

    /// Renders a whole frame of the dataset (any split).
    pub fn render_frame(&self, data: &TrainData, frame: &Frame) -> Result<ImageRgb> {
        self.render_frame_with(data, frame, true, true)
    }

    /// Renders a whole frame with the two savings of [`TeacherModel::render_frame`] each
    /// optional: `skip` samples only inside the head's bounds (off: every ray is sampled
    /// over its whole `[near, far]` span, as AD-NeRF renders), `early_stop` leaves a ray
    /// once its transmittance falls below `min_transmittance` (off: every sample is
    /// evaluated).
    pub fn render_frame_with(
        &self,
        data: &TrainData,
        frame: &Frame,
        skip: bool,
        early_stop: bool,
    ) -> Result<ImageRgb> {
        let ds = &data.dataset;
        let rays = rays_for_image(&ds.camera(frame));
        let codes = self.audio_codes(data, &[frame.aud_id])?;
        let bg = &ds.background.data;
        let mut range = data.head_range();
        if !skip {
            // A box holding every point within `far` of any camera.
            let reach = Vec3::splat(NO_SKIP_REACH);
            range.bounds = Bounds {
                lo: -reach,
                hi: reach,
            };
        }
        let min_transmittance = if early_stop {
            self.teacher.cfg.min_transmittance
        } else {
            0.0
        };
        let colors = self
            .teacher
            .render_eval(&rays, bg, &codes, &range, min_transmittance)?;
        Ok(ImageRgb {
            width: ds.intrinsics.width,
            height: ds.intrinsics.height,
            data: colors,
        })
    }

    /// Renders `n` validation frames spread evenly over the split and scores them.
    pub fn validation_scores(&self, data: &TrainData, n: usize) -> Result<Scores> {
        score_validation_frames(data, n, &|f| self.render_frame(data, f))
    }
}

/// A teacher being trained: the model, its optimizer and its training clock. It derefs to
/// its [`TeacherModel`], which renders.
pub struct TeacherRun {
    pub model: TeacherModel,
    adam: Adam,
    /// Rays of the last training step that hit the head's bounds.
    pub last_hit_rays: usize,
    clock: Clock,
}

/// One step's rays with their targets.
#[derive(Default)]
struct StepBatch {
    rays: Rays,
    /// Ground-truth colour per ray, `[n, 3]` flat.
    gt: Vec<f32>,
    /// Background colour per ray, `[n, 3]` flat.
    bg: Vec<f32>,
    /// Which of `picked` each ray belongs to.
    frame_of_ray: Vec<u32>,
    /// The training frames of the batch.
    picked: Vec<usize>,
    /// `(training frame index, i, j)` per ray.
    pixels: Vec<(usize, u32, u32)>,
}

impl TeacherRun {
    /// A new run in `dir` with seeded weights. The audio features' width and source are
    /// taken from the data.
    pub fn create(dir: &Path, mut cfg: TeacherRunConfig, data: &TrainData) -> Result<TeacherRun> {
        cfg.model.audio.set_from(&data.dataset);
        if let Some(grid) = &mut cfg.model.grid {
            // The grid spans the box the rays are sampled in.
            grid.set_box(data.bounds.lo, data.bounds.hi);
        }
        let run = Self::build(dir, cfg)?;
        let seed = run.model.cfg.train.seed;
        crate::networks::audio_net::init_with_centred_attention(
            &run.model.varmap,
            seed,
            run.model.cfg.model.audio.att_frames,
        )?;
        if let Some(occ) = &run.model.teacher.occupancy {
            occ.reset()?;
        }
        if run.model.cfg.model.grid.is_some() {
            crate::networks::hash_grid::init_table(
                &run.model.varmap,
                crate::networks::teacher::GRID_TABLE,
                seed,
            )?;
        }
        Ok(run)
    }

    /// Loads the run in `dir` to continue training: its `config.json`, weights and
    /// optimizer state. To render, [`TeacherModel::open`] reads the weights alone.
    pub fn open(dir: &Path) -> Result<TeacherRun> {
        let mut run = Self::build(dir, read_config(&dir.join(CONFIG_FILE))?)?;
        let (model, adam) = (&mut run.model, &mut run.adam);
        (model.step, run.clock) = open_checkpoint(dir, &model.varmap, Some(adam))?;
        Ok(run)
    }

    /// A run at step 0 with the network of `cfg` (weights as the variable builder made
    /// them) and a fresh optimizer.
    fn build(dir: &Path, cfg: TeacherRunConfig) -> Result<TeacherRun> {
        Self::from_model(TeacherModel::build(dir, cfg)?)
    }

    /// A run that trains on from `model`'s weights and step with a fresh optimizer (its
    /// moments at zero), its clock going on from the model's training time.
    pub fn from_model(model: TeacherModel) -> Result<TeacherRun> {
        let adam = new_adam(&model.varmap, &model.cfg)?;
        let clock = Clock::resumed(model.trained_s);
        Ok(TeacherRun {
            model,
            adam,
            last_hit_rays: 0,
            clock,
        })
    }

    /// Training seconds so far, across resumes.
    pub fn elapsed(&self) -> f64 {
        self.clock.elapsed()
    }

    /// The learning rate now: tenfold down over `lr_decay_steps`, or over the time budget
    /// when one is set and further along ([`crate::trainers::config::decayed_learning_rate`]).
    pub fn learning_rate(&self) -> f64 {
        let t = &self.model.cfg.train;
        crate::trainers::config::decayed_learning_rate(
            t.lr,
            self.model.step.saturating_sub(t.lr_hold_steps),
            t.lr_decay_steps,
            self.elapsed(),
            t.time_budget_s,
        )
    }

    /// The random stream of the current step's batch.
    fn step_rng(&self) -> ChaCha8Rng {
        let mut rng = ChaCha8Rng::seed_from_u64(self.model.cfg.train.seed);
        rng.set_stream(self.model.step as u64 + 1);
        rng
    }

    /// The rays of the current step's batch: `frames_per_batch` training frames, each with
    /// its share of rays, `mouth_fraction` of them from the frame's mouth region (when the
    /// dataset knows one), the rest [`sample_batch`]'s face-biased draw.
    fn sample_step_batch(&self, data: &TrainData, rng: &mut ChaCha8Rng) -> StepBatch {
        let t = &self.model.cfg.train;
        let frames = data.dataset.frames(Split::Train);
        let n_frames = t.frames_per_batch.min(frames.len()).max(1);
        let picked = sample_indices(rng, frames.len(), n_frames).into_vec();
        let per_frame = t.batch_rays.div_ceil(n_frames);
        let mut b = StepBatch {
            rays: Rays::with_capacity(per_frame * n_frames),
            ..StepBatch::default()
        };
        for (slot, &fi) in picked.iter().enumerate() {
            let frame = &frames[fi];
            let mouth = data.mouth_pixels.get(fi).map(Vec::as_slice).unwrap_or(&[]);
            let n_mouth = if mouth.is_empty() {
                0
            } else {
                ((t.mouth_fraction.clamp(0.0, 1.0) * per_frame as f32).round() as usize)
                    .min(per_frame)
            };
            let camera = data.dataset.camera(frame);
            let mut batch = sample_batch(
                &camera,
                frame.face_rect,
                per_frame - n_mouth,
                t.face_fraction,
                rng,
            );
            for _ in 0..n_mouth {
                let (i, j) = mouth[rng.random_range(0..mouth.len())];
                let (o, d) = camera.ray(i as f32, j as f32);
                batch.pixels.push((i, j));
                batch.rays.push(o, d);
            }
            for (r, &(i, j)) in batch.pixels.iter().enumerate() {
                b.rays.push(batch.rays.origin(r), batch.rays.direction(r));
                b.gt.extend_from_slice(&data.images[fi].get(i, j));
                b.bg.extend_from_slice(&data.dataset.background.get(i, j));
                b.frame_of_ray.push(slot as u32);
                b.pixels.push((fi, i, j));
            }
        }
        b.picked = picked;
        b
    }

    /// The pixels the current step trains on, as `(training frame index, i, j)`.
    pub fn step_pixels(&self, data: &TrainData) -> Vec<(usize, u32, u32)> {
        self.sample_step_batch(data, &mut self.step_rng()).pixels
    }

    /// One training step; returns the batch's loss (MSE over all its rays) and PSNR.
    pub fn train_step(&mut self, data: &TrainData) -> Result<(f64, f64)> {
        let mut rng = self.step_rng();
        let frames = data.dataset.frames(Split::Train);
        let StepBatch {
            rays,
            gt,
            bg,
            frame_of_ray,
            picked,
            ..
        } = self.sample_step_batch(data, &mut rng);
        let aud_ids: Vec<usize> = picked.iter().map(|&fi| frames[fi].aud_id).collect();
        let codes = self.model.audio_codes(data, &aud_ids)?;
        self.update_occupancy(&codes)?;
        let out = self.model.teacher.render(
            &rays,
            &bg,
            &codes,
            &frame_of_ray,
            &data.bounds,
            data.dataset.near,
            data.dataset.far,
            Some(&mut rng as &mut dyn RngCore),
        )?;
        let n = rays.len();
        self.last_hit_rays = out.hit.len();
        // Rays that miss the bounds are their background: a constant part of the loss.
        let mut hit_mask = vec![false; n];
        out.hit.iter().for_each(|&r| hit_mask[r] = true);
        let miss_sq: f64 = (0..n)
            .filter(|&r| !hit_mask[r])
            .map(|r| {
                (0..3)
                    .map(|c| (bg[3 * r + c] - gt[3 * r + c]) as f64)
                    .map(|d| d * d)
                    .sum::<f64>()
            })
            .sum();
        let gt_hit: Vec<f32> = out
            .hit
            .iter()
            .flat_map(|&r| gt[3 * r..3 * r + 3].iter().copied())
            .collect();
        let gt_hit = Tensor::from_vec(gt_hit, (out.hit.len(), 3), &Device::Cpu)?;
        let scale = 1.0 / (3 * n) as f64;
        let hit_sq = (&out.color - &gt_hit)?.sqr()?.sum_all()?;
        let loss = (hit_sq.affine(scale, miss_sq * scale))?;
        let value = finite_loss(&loss)?;
        let lr = self.learning_rate();
        let grads = loss.backward()?;
        self.adam.step(&grads, lr)?;
        self.model.step += 1;
        Ok((value, psnr_from_mse(value)))
    }

    /// Updates the teacher's occupancy grid when the step is due
    /// ([`crate::networks::occupancy::Occupancy::due`]):
    /// cell points from their own random stream of `(seed, step)`, the batch's `codes`.
    fn update_occupancy(&self, codes: &Tensor) -> Result<()> {
        let teacher = &self.model.teacher;
        let step = self.model.step;
        match &teacher.occupancy {
            Some(occ) if occ.due(step) => {
                let mut rng = ChaCha8Rng::seed_from_u64(self.model.cfg.train.seed ^ OCCUPANCY_SEED);
                rng.set_stream(step as u64 + 1);
                Ok(teacher.update_occupancy(codes, step, &mut rng)?)
            }
            _ => Ok(()),
        }
    }

    /// Writes the checkpoint (weights, optimizer state, config) into the run's folder.
    pub fn save(&self) -> Result<()> {
        let title = format!(
            "teacher {}x{}, {} rays/step",
            self.model.cfg.model.depth, self.model.cfg.model.width, self.model.cfg.train.batch_rays
        );
        std::fs::create_dir_all(&self.model.dir).map_err(|e| Error::io(&self.model.dir, e))?;
        save_json(&self.model.dir.join(CONFIG_FILE), &self.model.cfg)?;
        save_checkpoint(&CheckpointParts {
            dir: &self.model.dir,
            kind: "teacher",
            step: self.model.step,
            elapsed: self.elapsed(),
            varmap: &self.model.varmap,
            adam: &self.adam,
            title: &title,
        })
    }

    /// Trains until `cfg.train.iters` steps are done or `stop` is set (see [`train_loop`]).
    pub fn train(
        &mut self,
        data: &TrainData,
        stop: &AtomicBool,
        on_event: &mut dyn FnMut(&Event),
    ) -> Result<Option<Scores>> {
        train_loop(self, data, stop, on_event)
    }
}

impl TrainingRun for TeacherRun {
    run_fields!(TeacherRun);

    fn train_step(&mut self, data: &TrainData) -> Result<(f64, f64)> {
        TeacherRun::train_step(self, data)
    }
}

/// Mixed into the seed of the occupancy grid's cell points, apart from the batches' stream.
const OCCUPANCY_SEED: u64 = 0x6f63_6375_7079;

fn new_adam(varmap: &VarMap, cfg: &TeacherRunConfig) -> Result<Adam> {
    let t = &cfg.train;
    let mut scales = vec![("audio.att.", t.att_lr_scale)];
    if let Some(grid) = &cfg.model.grid {
        scales.push((crate::networks::teacher::GRID_TABLE, grid.lr_scale));
    }
    // The occupancy grid's densities are measured, not learned.
    let vars = scaled_vars(varmap, &scales)?
        .into_iter()
        .filter(|(name, _, _)| name != OCCUPANCY_VAR)
        .collect();
    Ok(Adam::new(
        vars,
        AdamParams {
            beta1: t.beta1,
            beta2: t.beta2,
            eps: t.eps,
        },
    ))
}
