//! The teacher's trainer: AD-NeRF's recipe (face-biased ray batches, Adam with exponential
//! learning-rate decay, AudioAttNet switched on late at a higher rate) with periodic
//! validation, `log.csv`, atomic checkpoints and bit-exact resume.
//!
//! Every step draws its batch from a generator seeded by `(seed, step)`, so a resumed run
//! sees exactly the batches an uninterrupted one would have seen.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use candle_core::{DType, Device, Tensor};
use candle_nn::VarMap;
use nldf_core::bounds::{Bounds, dataset_bounds};
use nldf_core::dataset::{AudioChoice, Dataset, Frame, Split};
use nldf_core::image::ImageRgb;
use nldf_core::metrics::{cap_psnr, psnr, psnr_from_mse, psnr_masked, ssim};
use nldf_core::rays::{Rays, rays_for_image, sample_batch};
use nldf_core::region::Region;
use rand::seq::index::sample as sample_indices;
use rand::{Rng, RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::adam::{Adam, AdamParams};
use crate::audio_net::neighbourhoods;
use crate::checkpoint::{load_tensors, restore_weights, save_json, save_tensors, step_of, weights};
use crate::config::{RunConfig, TeacherRunConfig, read_config};
use crate::error::{Error, Result};
use crate::nn::{init_seeded, new_varmap, sorted_vars};
use crate::teacher::{Teacher, teacher};
use nldf_core::run_files::{CONFIG_FILE, CURVE_FILE, LOG_FILE, MODEL_FILE, STATE_FILE};

/// A dataset prepared for training: decoded training frames and the head's bounds.
#[derive(Debug, Clone)]
pub struct TrainData {
    pub dataset: Dataset,
    /// Decoded images of the training frames, in split order.
    pub images: Vec<ImageRgb>,
    /// Per training frame, its mouth pixels (`i`, `j`) from the parsing masks (empty
    /// without masks or when not decoded).
    pub mouth_pixels: Vec<Vec<(u32, u32)>>,
    pub bounds: Bounds,
}

impl TrainData {
    /// Loads and validates a dataset and decodes its training frames.
    pub fn load(root: &Path) -> Result<TrainData> {
        Self::open(root, true)
    }

    /// Loads and validates a dataset; decodes the training frames only with `decode`
    /// (rendering and evaluation need none).
    pub fn open(root: &Path, decode: bool) -> Result<TrainData> {
        Self::open_with(root, decode, &AudioChoice::Auto)
    }

    /// [`TrainData::open`] with the audio features `audio` says (a trained run's, say).
    pub fn open_with(root: &Path, decode: bool, audio: &AudioChoice) -> Result<TrainData> {
        let dataset = Dataset::load_with(root, audio)?;
        let (mut images, mut mouth_pixels) = (Vec::new(), Vec::new());
        if decode {
            let width = dataset.intrinsics.width as usize;
            for f in dataset.frames(Split::Train) {
                images.push(dataset.load_image(f)?);
                let mouth = match dataset.load_regions(f)? {
                    Some(regions) => regions
                        .iter()
                        .enumerate()
                        .filter(|(_, r)| **r == Region::Mouth)
                        .map(|(p, _)| ((p % width) as u32, (p / width) as u32))
                        .collect(),
                    None => Vec::new(),
                };
                mouth_pixels.push(mouth);
            }
        }
        let bounds = dataset_bounds(&dataset)?;
        Ok(TrainData {
            dataset,
            images,
            mouth_pixels,
            bounds,
        })
    }
}

/// What the trainer reports as it goes.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// A training step finished.
    Step {
        step: usize,
        loss: f64,
        psnr: f64,
        rays_per_s: f64,
    },
    /// Validation frames were rendered and scored.
    Validation { step: usize, scores: Scores },
    /// A checkpoint was written.
    Checkpoint { step: usize, dir: PathBuf },
}

/// Image scores averaged over frames.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Scores {
    pub psnr: f64,
    pub ssim: f64,
    /// PSNR inside the head (face, eyes, mouth; when the dataset has parsing masks).
    pub face_psnr: Option<f64>,
    /// PSNR inside the mouth region (when the dataset has parsing masks).
    pub mouth_psnr: Option<f64>,
    pub frames: usize,
    /// Frames whose render holds a NaN or infinite value: their scores are NaN, and so are
    /// the means above.
    #[serde(default)]
    pub non_finite: usize,
}

/// PSNR inside the head and inside the mouth (each `None` where the region is empty),
/// capped at [`nldf_core::metrics::PSNR_CAP`] dB (a NaN stays NaN).
pub fn region_psnrs(
    render: &ImageRgb,
    truth: &ImageRgb,
    regions: &[Region],
) -> Result<(Option<f64>, Option<f64>)> {
    let head: Vec<bool> = regions.iter().map(|r| r.is_head()).collect();
    let mouth: Vec<bool> = regions.iter().map(|r| *r == Region::Mouth).collect();
    Ok((
        psnr_masked(render, truth, &head)?.map(cap_psnr),
        psnr_masked(render, truth, &mouth)?.map(cap_psnr),
    ))
}

/// Renders `n` validation frames spread evenly over the validation split (the training
/// split when it is empty) with `render` and scores them.
pub fn validate_frames(
    data: &TrainData,
    n: usize,
    render: &dyn Fn(&Frame) -> Result<ImageRgb>,
) -> Result<Scores> {
    let frames = data.dataset.frames(Split::Val);
    let frames = if frames.is_empty() {
        data.dataset.frames(Split::Train)
    } else {
        frames
    };
    let n = n.clamp(1, frames.len().max(1));
    let mut pairs = Vec::with_capacity(n);
    for k in 0..n.min(frames.len()) {
        let frame = &frames[k * frames.len() / n];
        let truth = data.dataset.load_image(frame)?;
        let regions = data.dataset.load_regions(frame)?;
        pairs.push((render(frame)?, truth, regions));
    }
    score_frames(&pairs)
}

/// Scores of rendered frames against their ground truth and optional region masks. A
/// render holding a NaN or infinite value makes every mean NaN and is counted in
/// [`Scores::non_finite`]: it never scores as a good frame.
pub fn score_frames(pairs: &[(ImageRgb, ImageRgb, Option<Vec<Region>>)]) -> Result<Scores> {
    let (mut p, mut s) = (0.0, 0.0);
    let (mut face, mut mouth) = (Vec::new(), Vec::new());
    let mut non_finite = 0;
    for (render, truth, regions) in pairs {
        non_finite += usize::from(render.non_finite_values() > 0);
        p += cap_psnr(psnr(render, truth)?);
        s += ssim(render, truth)?;
        if let Some(regions) = regions {
            let (f, m) = region_psnrs(render, truth, regions)?;
            face.extend(f);
            mouth.extend(m);
        }
    }
    let n = pairs.len().max(1) as f64;
    let mean = |v: Vec<f64>| (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64);
    Ok(Scores {
        psnr: p / n,
        ssim: s / n,
        face_psnr: mean(face),
        mouth_psnr: mean(mouth),
        frames: pairs.len(),
        non_finite,
    })
}

/// A teacher being trained: its folder, configuration, weights and optimizer.
pub struct TeacherRun {
    pub dir: PathBuf,
    pub cfg: TeacherRunConfig,
    pub varmap: VarMap,
    pub teacher: Teacher,
    adam: Adam,
    /// Steps done.
    pub step: usize,
    /// Training seconds before this process (from the checkpoint).
    elapsed_before: f64,
    /// Rays of the last training step that hit the head's bounds.
    pub last_hit_rays: usize,
    started: Instant,
}

impl TeacherRun {
    /// A new run in `dir` with seeded weights. The audio features' width and source are
    /// taken from the data.
    pub fn create(dir: &Path, mut cfg: TeacherRunConfig, data: &TrainData) -> Result<TeacherRun> {
        cfg.model.audio.set_from(&data.dataset);
        let run = Self::build(dir, cfg)?;
        init_seeded(&run.varmap, run.cfg.train.seed)?;
        crate::audio_net::centre_attention(&run.varmap, "audio", run.cfg.model.audio.att_frames)?;
        Ok(run)
    }

    /// Loads the run in `dir` (its `config.json`, weights and, with `optimizer`, the
    /// optimizer state) to continue training or to render.
    pub fn open(dir: &Path, optimizer: bool) -> Result<TeacherRun> {
        let mut run = Self::build(dir, read_config(&dir.join(CONFIG_FILE))?)?;
        let (step, elapsed) =
            open_checkpoint(dir, &run.varmap, optimizer.then_some(&mut run.adam))?;
        run.step = step;
        run.elapsed_before = elapsed;
        Ok(run)
    }

    /// A run at step 0 with the network of `cfg` (weights as the variable builder made
    /// them) and a fresh optimizer.
    fn build(dir: &Path, cfg: TeacherRunConfig) -> Result<TeacherRun> {
        cfg.check()?;
        let (varmap, vb) = new_varmap();
        let teacher = teacher(&cfg.model, vb)?;
        let adam = new_adam(&varmap, &cfg)?;
        Ok(TeacherRun {
            dir: dir.to_path_buf(),
            cfg,
            varmap,
            teacher,
            adam,
            step: 0,
            elapsed_before: 0.0,
            last_hit_rays: 0,
            started: Instant::now(),
        })
    }

    /// Training seconds so far, across resumes.
    pub fn elapsed(&self) -> f64 {
        self.elapsed_before + self.started.elapsed().as_secs_f64()
    }

    /// The learning rate at the current step: `lr 0.1^(step / lr_decay_steps)`.
    pub fn learning_rate(&self) -> f64 {
        let t = &self.cfg.train;
        t.lr * 0.1f64.powf(self.step as f64 / t.lr_decay_steps.max(1) as f64)
    }

    fn attention_on(&self) -> bool {
        self.step >= self.cfg.train.att_start
    }

    /// Audio codes of `frames` (indices into the dataset's audio windows).
    ///
    /// # Shapes
    /// - returns `[frames.len(), audio_dim]`
    pub fn audio_codes(&self, data: &TrainData, aud_ids: &[usize]) -> Result<Tensor> {
        let windows = neighbourhoods(
            &data.dataset.audio,
            aud_ids,
            self.cfg.model.audio.att_frames,
        )?;
        Ok(self.teacher.audio.forward(&windows, self.attention_on())?)
    }

    /// One training step; returns the batch's loss (MSE over all its rays) and PSNR.
    pub fn train_step(&mut self, data: &TrainData) -> Result<(f64, f64)> {
        let t = self.cfg.train.clone();
        let mut rng = ChaCha8Rng::seed_from_u64(t.seed);
        rng.set_stream(self.step as u64 + 1);
        let frames = data.dataset.frames(Split::Train);
        let n_frames = t.frames_per_batch.min(frames.len()).max(1);
        let picked = sample_indices(&mut rng, frames.len(), n_frames).into_vec();
        let per_frame = t.batch_rays.div_ceil(n_frames);
        let mut rays = Rays::with_capacity(per_frame * n_frames);
        let (mut gt, mut bg, mut frame_of_ray) = (Vec::new(), Vec::new(), Vec::new());
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
                &mut rng,
            );
            for _ in 0..n_mouth {
                let (i, j) = mouth[rng.random_range(0..mouth.len())];
                let (o, d) = camera.ray(i as f32, j as f32);
                batch.pixels.push((i, j));
                batch.rays.push(o, d);
            }
            for (r, &(i, j)) in batch.pixels.iter().enumerate() {
                rays.push(batch.rays.origin(r), batch.rays.direction(r));
                gt.extend_from_slice(&data.images[fi].get(i, j));
                bg.extend_from_slice(&data.dataset.background.get(i, j));
                frame_of_ray.push(slot as u32);
            }
        }
        let aud_ids: Vec<usize> = picked.iter().map(|&fi| frames[fi].aud_id).collect();
        let codes = self.audio_codes(data, &aud_ids)?;
        let out = self.teacher.render(
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
        self.step += 1;
        Ok((value, psnr_from_mse(value)))
    }

    /// Renders a whole frame of the dataset (any split).
    pub fn render_frame(&self, data: &TrainData, frame: &Frame) -> Result<ImageRgb> {
        let ds = &data.dataset;
        let rays = rays_for_image(&ds.camera(frame));
        let codes = self.audio_codes(data, &[frame.aud_id])?;
        let bg = &ds.background.data;
        let colors = self
            .teacher
            .render_eval(&rays, bg, &codes, &data.bounds, ds.near, ds.far)?;
        Ok(ImageRgb {
            width: ds.intrinsics.width,
            height: ds.intrinsics.height,
            data: colors,
        })
    }

    /// Renders `n` validation frames spread evenly over the split and scores them.
    pub fn validate(&self, data: &TrainData, n: usize) -> Result<Scores> {
        validate_frames(data, n, &|f| self.render_frame(data, f))
    }

    /// Writes the checkpoint (weights, optimizer state, config) into the run's folder.
    pub fn save(&self) -> Result<()> {
        let title = format!(
            "teacher {}x{}, {} rays/step",
            self.cfg.model.depth, self.cfg.model.width, self.cfg.train.batch_rays
        );
        std::fs::create_dir_all(&self.dir).map_err(|e| Error::io(&self.dir, e))?;
        save_json(&self.dir.join(CONFIG_FILE), &self.cfg)?;
        save_checkpoint(&CheckpointParts {
            dir: &self.dir,
            kind: "teacher",
            step: self.step,
            elapsed: self.elapsed(),
            varmap: &self.varmap,
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
    fn dir(&self) -> &Path {
        &self.dir
    }

    fn step(&self) -> usize {
        self.step
    }

    fn schedule(&self) -> Schedule {
        let t = &self.cfg.train;
        Schedule {
            iters: t.iters,
            batch_rays: t.batch_rays,
            log_every: t.log_every,
            val_every: t.val_every,
            val_frames: t.val_frames,
            checkpoint_every: t.checkpoint_every,
            time_budget_s: t.time_budget_s,
        }
    }

    fn elapsed(&self) -> f64 {
        TeacherRun::elapsed(self)
    }

    fn learning_rate(&self) -> f64 {
        TeacherRun::learning_rate(self)
    }

    fn train_step(&mut self, data: &TrainData) -> Result<(f64, f64)> {
        TeacherRun::train_step(self, data)
    }

    fn validate(&self, data: &TrainData, n: usize) -> Result<Scores> {
        TeacherRun::validate(self, data, n)
    }

    fn save(&self) -> Result<()> {
        TeacherRun::save(self)
    }
}

/// When a training loop validates, logs, checkpoints and stops.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Schedule {
    pub iters: usize,
    pub batch_rays: usize,
    pub log_every: usize,
    pub val_every: usize,
    pub val_frames: usize,
    pub checkpoint_every: usize,
    pub time_budget_s: f64,
}

/// A model being trained, as [`train_loop`] sees it (the teacher and the student).
pub trait TrainingRun {
    /// The run's folder.
    fn dir(&self) -> &Path;
    /// Steps done.
    fn step(&self) -> usize;
    fn schedule(&self) -> Schedule;
    /// Training seconds so far, across resumes.
    fn elapsed(&self) -> f64;
    fn learning_rate(&self) -> f64;
    /// One step; returns the batch's loss and PSNR.
    fn train_step(&mut self, data: &TrainData) -> Result<(f64, f64)>;
    /// Scores `n` validation frames.
    fn validate(&self, data: &TrainData, n: usize) -> Result<Scores>;
    /// Writes the checkpoint.
    fn save(&self) -> Result<()>;
}

/// The value of a scalar loss, or [`Error::NonFinite`] when it is NaN or infinite (checked
/// before the backward pass, so that a diverged step changes no weight).
pub fn finite_loss(loss: &Tensor) -> Result<f64> {
    let value = loss.to_dtype(DType::F64)?.to_scalar::<f64>()?;
    if value.is_finite() {
        Ok(value)
    } else {
        Err(Error::NonFinite(format!("the loss is {value}")))
    }
}

/// Trains until the schedule's steps are done, its time budget is spent or `stop` is set,
/// validating, logging to `log.csv` and checkpointing as scheduled; always leaves a
/// checkpoint of the last step. Returns the final validation scores when it ran to the end.
///
/// A loss or gradient that becomes NaN or infinite, or a validation render that does,
/// stops the run with [`Error::NonFinite`] naming the step: nothing is checkpointed after
/// it, so the last checkpoint on disk is the last good one.
pub fn train_loop(
    run: &mut dyn TrainingRun,
    data: &TrainData,
    stop: &AtomicBool,
    on_event: &mut dyn FnMut(&Event),
) -> Result<Option<Scores>> {
    let dir = run.dir().to_path_buf();
    std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
    let mut log = crate::log::CsvLog::open(&dir.join(LOG_FILE), run.step())?;
    let t = run.schedule();
    let mut last_val = None;
    let mut saved = (run.step() > 0).then_some(run.step());
    let diverged = |step: usize, what: String, saved: Option<usize>| {
        let kept = match saved {
            Some(s) => format!("the checkpoint of step {s} in {} is kept", dir.display()),
            None => "no checkpoint was written".to_string(),
        };
        Error::NonFinite(format!(
            "training diverged at step {step}: {what}; {kept}; lower the learning rate (`lr`) \
             and train again"
        ))
    };
    while run.step() < t.iters {
        if stop.load(Ordering::Relaxed) {
            run.save()?;
            on_event(&Event::Checkpoint {
                step: run.step(),
                dir: dir.clone(),
            });
            return Ok(None);
        }
        let started = Instant::now();
        let (loss, psnr) = match run.train_step(data) {
            Ok(v) => v,
            Err(Error::NonFinite(what)) => return Err(diverged(run.step() + 1, what, saved)),
            Err(e) => return Err(e),
        };
        let rays_per_s = t.batch_rays as f64 / started.elapsed().as_secs_f64().max(1e-9);
        let step = run.step();
        on_event(&Event::Step {
            step,
            loss,
            psnr,
            rays_per_s,
        });
        let out_of_time = t.time_budget_s > 0.0 && run.elapsed() >= t.time_budget_s;
        let last = step == t.iters || out_of_time;
        let validate_now = (t.val_every > 0 && step.is_multiple_of(t.val_every)) || last;
        let scores = if validate_now {
            let s = run.validate(data, t.val_frames)?;
            if s.non_finite > 0 {
                let what = format!(
                    "{} of {} validation renders hold NaN or infinite values",
                    s.non_finite, s.frames
                );
                return Err(diverged(step, what, saved));
            }
            on_event(&Event::Validation { step, scores: s });
            last_val = Some(s);
            Some(s)
        } else {
            None
        };
        if step.is_multiple_of(t.log_every.max(1)) || scores.is_some() {
            log.row(
                step,
                run.elapsed(),
                loss,
                psnr,
                run.learning_rate(),
                rays_per_s,
                scores,
            )?;
        }
        if (t.checkpoint_every > 0 && step.is_multiple_of(t.checkpoint_every)) || last {
            run.save()?;
            saved = Some(step);
            on_event(&Event::Checkpoint {
                step,
                dir: dir.clone(),
            });
        }
        if out_of_time {
            break;
        }
    }
    Ok(last_val)
}

/// What [`save_checkpoint`] writes.
pub struct CheckpointParts<'a> {
    pub dir: &'a Path,
    /// `teacher` or `student`, in the safetensors metadata.
    pub kind: &'a str,
    pub step: usize,
    pub elapsed: f64,
    pub varmap: &'a VarMap,
    pub adam: &'a Adam,
    /// Title of the training-curve plot.
    pub title: &'a str,
}

/// Writes the optimizer state, then the weights (each atomically, with the step in their
/// metadata), and redraws the training curve from `log.csv`. The caller writes its config.
pub fn save_checkpoint(parts: &CheckpointParts) -> Result<()> {
    let dir = parts.dir;
    let weights = weights(parts.varmap)?;
    if let Some(name) = first_non_finite(&weights)? {
        return Err(Error::NonFinite(format!(
            "refusing to checkpoint {}: weight `{name}` holds a NaN or infinite value",
            dir.display()
        )));
    }
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let meta = |kind: &str| {
        [
            ("step".to_string(), parts.step.to_string()),
            ("elapsed_s".to_string(), format!("{:.3}", parts.elapsed)),
            ("kind".to_string(), kind.to_string()),
        ]
        .into_iter()
        .collect()
    };
    save_tensors(
        &dir.join(STATE_FILE),
        &parts.adam.state()?,
        meta("optimizer"),
    )?;
    save_tensors(&dir.join(MODEL_FILE), &weights, meta(parts.kind))?;
    let log = dir.join(LOG_FILE);
    if log.is_file() {
        let rows = crate::log::read_log(&log)?;
        crate::plot::plot_training_curve(&dir.join(CURVE_FILE), parts.title, &rows)?;
    }
    Ok(())
}

/// The name of the first tensor (in name order) holding a NaN or infinite value.
pub fn first_non_finite(tensors: &HashMap<String, Tensor>) -> Result<Option<String>> {
    let mut names: Vec<&String> = tensors.keys().collect();
    names.sort();
    for name in names {
        let values: Vec<f32> = tensors[name]
            .flatten_all()?
            .to_dtype(DType::F32)?
            .to_vec1()?;
        if values.iter().any(|v| !v.is_finite()) {
            return Ok(Some(name.clone()));
        }
    }
    Ok(None)
}

/// Restores the weights in `dir` into `varmap` and, given `adam`, the optimizer state
/// (checking that both come from the same step). Returns the step and the training seconds.
pub fn open_checkpoint(
    dir: &Path,
    varmap: &VarMap,
    adam: Option<&mut Adam>,
) -> Result<(usize, f64)> {
    let model_path = dir.join(MODEL_FILE);
    let (tensors, meta) = load_tensors(&model_path)?;
    restore_weights(&model_path, varmap, &tensors)?;
    let step = step_of(&model_path, &meta)?;
    let elapsed = meta
        .get("elapsed_s")
        .and_then(|s| s.parse().ok())
        .unwrap_or(0.0);
    if let Some(adam) = adam {
        let state_path = dir.join(STATE_FILE);
        let (state, state_meta) = load_tensors(&state_path)?;
        let state_step = step_of(&state_path, &state_meta)?;
        if state_step != step {
            return Err(Error::invalid(
                &state_path,
                format!(
                    "is from step {state_step} but {MODEL_FILE} from step {step}; the last checkpoint was cut short"
                ),
            ));
        }
        adam.load_state(&state)
            .map_err(|e| Error::invalid(&state_path, e.to_string()))?;
    }
    Ok((step, elapsed))
}

fn new_adam(varmap: &VarMap, cfg: &TeacherRunConfig) -> Result<Adam> {
    let t = &cfg.train;
    let vars = sorted_vars(varmap)?
        .into_iter()
        .map(|(name, var)| {
            let scale = if name.starts_with("audio.att.") {
                t.att_lr_scale
            } else {
                1.0
            };
            (name, var, scale)
        })
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
