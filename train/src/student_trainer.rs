//! The student's trainer (paper sections 3.4-3.5): beams through the pixels whose rays hit
//! the head's bounds, 90 % of them inside `face_rect`; the loss of Eq. 9 (pixel loss plus
//! lambda times the segment loss against the frozen teacher's Eq. 5 colours); the active
//! beam pool trained as an extra batch that reaches the light field only; Adam, `log.csv`,
//! validation, atomic checkpoints and bit-exact resume as for the teacher.
//!
//! The teacher's segment colours are computed once per training pixel and cached in
//! `targets.safetensors`: a 2-core machine renders the teacher at a few thousand rays per
//! second, and training visits every pixel many times.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use candle_core::{D, Device, Tensor};
use candle_nn::VarMap;
use nldf_core::beam::encode_beams_parallel;
use nldf_core::camera::{Camera, turn_about};
use nldf_core::dataset::{Frame, Split};
use nldf_core::image::ImageRgb;
use nldf_core::metrics::psnr_from_mse;
use nldf_core::rays::{Rays, head_rays};
use nldf_core::render_spec::RenderSpec;
use nldf_core::run_files::{
    BACKGROUND_FILE, CONFIG_FILE, POOL_FILE, RENDER_SPEC_FILE, TARGETS_FILE,
};
use rand::seq::index::sample as sample_indices;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::adam::{Adam, AdamParams};
use crate::audio_net::neighbourhoods;
use crate::checkpoint::{load_tensors, save_json, save_tensors, step_of};
use crate::config::{RunConfig, StudentRunConfig, StudentTrainConfig, read_config};
use crate::error::{Error, Result};
use crate::nn::{init_seeded, new_varmap, sorted_vars};
use crate::pool::{BeamPool, PoolEntry};
use crate::student::{Student, student};
use crate::trainer::{
    CheckpointParts, Schedule, Scores, TeacherRun, TrainData, TrainingRun, finite_loss,
    open_checkpoint, save_checkpoint, validate_frames,
};

/// Rays per forward pass when rendering.
const RENDER_CHUNK: usize = 8192;

/// The pixels of one training frame whose rays hit the head's bounds (the only ones the
/// student sees), split by where they lie.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameBeams {
    /// `(i, j)` of every hit pixel, in row-major order.
    pub pixels: Vec<(u32, u32)>,
    /// Indices into `pixels`: inside `face_rect`, outside it, inside the mouth region.
    pub face: Vec<u32>,
    pub other: Vec<u32>,
    pub mouth: Vec<u32>,
}

/// A view the student learns from: a training frame, or a pseudo view (R2L's pseudo data)
/// whose pose and audio lie between the training frames'.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    pub camera: Camera,
    /// Audio ids whose codes are mixed: `weight code(a) + (1 - weight) code(b)`.
    pub audio: (usize, usize),
    pub weight: f32,
    /// The training frame the view comes from (its face and mouth regions are used).
    pub source: usize,
    /// Whether the view is a training frame, with a ground-truth image.
    pub recorded: bool,
}

/// The training frames as views, then `cfg.pseudo_frames` pseudo views (with distillation
/// on): each a seeded training frame's camera turned about the head's centre by up to
/// `pseudo_yaw_deg` and `pseudo_pitch_deg`, with the audio codes of two seeded training
/// frames mixed by a uniform weight.
pub fn training_views(data: &TrainData, cfg: &StudentTrainConfig) -> Vec<View> {
    let ds = &data.dataset;
    let frames = ds.frames(Split::Train);
    let mut views: Vec<View> = frames
        .iter()
        .enumerate()
        .map(|(fi, f)| View {
            camera: ds.camera(f),
            audio: (f.aud_id, f.aud_id),
            weight: 1.0,
            source: fi,
            recorded: true,
        })
        .collect();
    if !cfg.distill || frames.is_empty() {
        return views;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x5eed_5eed);
    let centre = 0.5 * (data.bounds.lo + data.bounds.hi);
    for _ in 0..cfg.pseudo_frames {
        let source = rng.random_range(0..frames.len());
        let other = rng.random_range(0..frames.len());
        let weight: f32 = rng.random_range(0.0..=1.0);
        let yaw = cfg.pseudo_yaw_deg.to_radians() * rng.random_range(-1.0f32..=1.0);
        let pitch = cfg.pseudo_pitch_deg.to_radians() * rng.random_range(-1.0f32..=1.0);
        let base = ds.camera(&frames[source]);
        views.push(View {
            camera: Camera {
                intrinsics: base.intrinsics,
                c2w: turn_about(centre, yaw, pitch) * base.c2w,
            },
            audio: (frames[source].aud_id, frames[other].aud_id),
            weight,
            source,
            recorded: false,
        });
    }
    views
}

/// The hit pixels of every view; a view's face and mouth regions are its source frame's.
pub fn frame_beams(data: &TrainData, views: &[View]) -> Vec<FrameBeams> {
    let ds = &data.dataset;
    let frames = ds.frames(Split::Train);
    let width = ds.intrinsics.width;
    views
        .par_iter()
        .map(|view| {
            let frame = &frames[view.source];
            let mouth: std::collections::HashSet<(u32, u32)> = data
                .mouth_pixels
                .get(view.source)
                .map(|m| m.iter().copied().collect())
                .unwrap_or_default();
            let head = head_rays(&view.camera, &data.bounds, ds.near, ds.far);
            let mut fb = FrameBeams::default();
            for r in 0..head.pixels.len() {
                let (i, j) = head.pixel_ij(r, width);
                let k = fb.pixels.len() as u32;
                fb.pixels.push((i, j));
                if frame.face_rect.contains(i, j) {
                    fb.face.push(k);
                } else {
                    fb.other.push(k);
                }
                if mouth.contains(&(i, j)) {
                    fb.mouth.push(k);
                }
            }
            fb
        })
        .collect()
}

/// The audio codes of `views`: `weight code(a) + (1 - weight) code(b)` row by row, with
/// `codes(ids)` the encoder's codes of audio ids (`[ids.len(), dim]`). Recorded frames
/// (weight 1) need only their own code, so the second encoder call is made only for
/// batches holding a pseudo view.
///
/// # Shapes
/// - returns `[views.len(), dim]`
fn codes_of_views(views: &[&View], codes: impl Fn(&[usize]) -> Result<Tensor>) -> Result<Tensor> {
    let a: Vec<usize> = views.iter().map(|v| v.audio.0).collect();
    let codes_a = codes(&a)?;
    if views.iter().all(|v| v.weight == 1.0) {
        return Ok(codes_a);
    }
    let b: Vec<usize> = views.iter().map(|v| v.audio.1).collect();
    let n = views.len();
    let dev = codes_a.device().clone();
    let w = Tensor::from_vec(views.iter().map(|v| v.weight).collect(), (n, 1), &dev)?;
    let rest = Tensor::from_vec(views.iter().map(|v| 1.0 - v.weight).collect(), (n, 1), &dev)?;
    Ok((codes_a.broadcast_mul(&w)? + codes(&b)?.broadcast_mul(&rest)?)?)
}

/// The teacher's Eq. 5 segment colours of every hit pixel of every view (`[n_pixels, m,
/// 3]` flat per view). `progress(done, total)` is called per view.
pub fn teacher_targets(
    teacher: &TeacherRun,
    data: &TrainData,
    views: &[View],
    beams: &[FrameBeams],
    m: usize,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Vec<Vec<f32>>> {
    let ds = &data.dataset;
    let mut out = Vec::with_capacity(views.len());
    for (vi, (view, fb)) in views.iter().zip(beams).enumerate() {
        let mut rays = Rays::with_capacity(fb.pixels.len());
        let mut bg = Vec::with_capacity(3 * fb.pixels.len());
        for &(i, j) in &fb.pixels {
            let (o, d) = view.camera.ray(i as f32, j as f32);
            rays.push(o, d);
            bg.extend_from_slice(&ds.background.get(i, j));
        }
        let code = codes_of_views(&[view], |ids| teacher.audio_codes(data, ids))?;
        out.push(teacher.teacher.segment_targets(
            &rays,
            &bg,
            &code,
            &data.bounds,
            ds.near,
            ds.far,
            m,
        )?);
        progress(vi + 1, views.len());
    }
    Ok(out)
}

/// One beam of a batch: training frame and hit-pixel index.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct BeamRef {
    frame: u32,
    pixel: u32,
}

/// What a training step reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StudentStep {
    /// Eq. 9 over the whole batch (pool beams included).
    pub loss: f64,
    /// PSNR of the main batch's pixels.
    pub psnr: f64,
    /// Beams that entered the pool.
    pub entered_pool: usize,
    /// Pool beams trained this step.
    pub pool_beams: usize,
}

/// A student being trained: folder, configuration, weights, optimizer, pool and the cached
/// per-frame beams and teacher targets.
pub struct StudentRun {
    pub dir: PathBuf,
    pub cfg: StudentRunConfig,
    pub varmap: VarMap,
    pub student: Student,
    adam: Adam,
    pub step: usize,
    elapsed_before: f64,
    started: Instant,
    pub pool: BeamPool,
    /// The training frames, then the pseudo views (set by [`StudentRun::prepare`]).
    pub views: Vec<View>,
    /// Hit pixels per view.
    pub beams: Vec<FrameBeams>,
    /// Teacher segment colours per view, aligned with `beams` (distillation).
    pub targets: Vec<Vec<f32>>,
}

impl StudentRun {
    /// A new run in `dir` with seeded weights. The audio feature width comes from the data;
    /// with a teacher, the student's audio encoder starts as the teacher's (same shape and
    /// weights, attention as the teacher last used it).
    pub fn create(
        dir: &Path,
        mut cfg: StudentRunConfig,
        data: &TrainData,
        teacher: Option<&TeacherRun>,
    ) -> Result<StudentRun> {
        cfg.model.audio.set_from(&data.dataset);
        if let Some(t) = teacher {
            if t.cfg.model.audio.features != data.dataset.audio_source {
                return Err(Error::Config(format!(
                    "the teacher was trained on {} but the dataset's audio is {} from {}",
                    t.cfg.model.audio.features.describe(),
                    data.dataset.audio_source.describe(),
                    data.dataset.audio_file.display()
                )));
            }
            cfg.model.audio = t.cfg.model.audio.clone();
            cfg.model.attention = t.step >= t.cfg.train.att_start;
        }
        let run = Self::build(dir, cfg)?;
        init_seeded(&run.varmap, run.cfg.train.seed)?;
        crate::audio_net::centre_attention(&run.varmap, "audio", run.cfg.model.audio.att_frames)?;
        if let Some(t) = teacher {
            let theirs = sorted_vars(&t.varmap)?
                .into_iter()
                .collect::<HashMap<String, candle_core::Var>>();
            for (name, var) in sorted_vars(&run.varmap)? {
                if name.starts_with("audio.")
                    && let Some(src) = theirs.get(&name)
                {
                    var.set(src.as_tensor())?;
                }
            }
        }
        Ok(run)
    }

    /// Loads the run in `dir` (config, weights, pool and, with `optimizer`, the optimizer
    /// state).
    pub fn open(dir: &Path, optimizer: bool) -> Result<StudentRun> {
        let mut run = Self::build(dir, read_config(&dir.join(CONFIG_FILE))?)?;
        let (step, elapsed) =
            open_checkpoint(dir, &run.varmap, optimizer.then_some(&mut run.adam))?;
        run.step = step;
        run.elapsed_before = elapsed;
        let pool_path = dir.join(POOL_FILE);
        if optimizer && pool_path.is_file() {
            run.pool = load_pool(&pool_path, run.pool.capacity, step)?;
        }
        Ok(run)
    }

    fn build(dir: &Path, cfg: StudentRunConfig) -> Result<StudentRun> {
        cfg.check()?;
        let (varmap, vb) = new_varmap();
        let student = student(&cfg.model, vb)?;
        let t = &cfg.train;
        let vars = sorted_vars(&varmap)?
            .into_iter()
            .map(|(name, var)| (name, var, 1.0))
            .collect();
        let adam = Adam::new(
            vars,
            AdamParams {
                beta1: t.beta1,
                beta2: t.beta2,
                eps: t.eps,
            },
        );
        let capacity = t.pool_batches * t.batch_rays;
        Ok(StudentRun {
            dir: dir.to_path_buf(),
            pool: BeamPool::new(capacity),
            cfg,
            varmap,
            student,
            adam,
            step: 0,
            elapsed_before: 0.0,
            started: Instant::now(),
            views: Vec::new(),
            beams: Vec::new(),
            targets: Vec::new(),
        })
    }

    /// Makes the views (training frames and pseudo views), finds their hit pixels and,
    /// when distilling, the teacher's segment colours: read from `targets.safetensors` when
    /// it matches the views and the teacher's step, otherwise computed with `teacher` and
    /// cached. Writes `render.json` and the background beside the checkpoint.
    pub fn prepare(
        &mut self,
        data: &TrainData,
        teacher: Option<&TeacherRun>,
        progress: &mut dyn FnMut(usize, usize),
    ) -> Result<()> {
        std::fs::create_dir_all(&self.dir).map_err(|e| Error::io(&self.dir, e))?;
        self.views = training_views(data, &self.cfg.train);
        self.beams = frame_beams(data, &self.views);
        let spec =
            RenderSpec::of_dataset(&data.dataset, data.bounds, self.cfg.model.audio.att_frames);
        spec.save(&self.dir.join(RENDER_SPEC_FILE))?;
        data.dataset
            .background
            .save_png(&self.dir.join(BACKGROUND_FILE))?;
        if !self.cfg.train.distill {
            return Ok(());
        }
        let m = self.cfg.model.segments;
        let path = self.dir.join(TARGETS_FILE);
        let teacher_step = teacher.map(|t| t.step);
        let fingerprint = views_fingerprint(&self.views);
        if path.is_file()
            && let Some(cached) = load_targets(&path, &self.beams, m, teacher_step, &fingerprint)?
        {
            self.targets = cached;
            return Ok(());
        }
        let teacher = teacher.ok_or_else(|| {
            Error::Config(format!(
                "distillation needs the teacher's segment colours: {} is missing and no teacher was given",
                path.display()
            ))
        })?;
        self.targets = teacher_targets(teacher, data, &self.views, &self.beams, m, progress)?;
        save_targets(&path, &self.targets, m, teacher.step, &fingerprint)
    }

    /// Training seconds so far, across resumes.
    pub fn elapsed(&self) -> f64 {
        self.elapsed_before + self.started.elapsed().as_secs_f64()
    }

    /// The learning rate at the current step ([`StudentTrainConfig::learning_rate`]).
    pub fn learning_rate(&self) -> f64 {
        self.cfg.train.learning_rate(self.step)
    }

    /// Audio codes of frames.
    ///
    /// # Shapes
    /// - returns `[aud_ids.len(), audio_dim]`
    pub fn audio_codes(&self, data: &TrainData, aud_ids: &[usize]) -> Result<Tensor> {
        let windows = neighbourhoods(
            &data.dataset.audio,
            aud_ids,
            self.cfg.model.audio.att_frames,
        )?;
        Ok(self.student.audio_codes(&windows)?)
    }

    /// Audio codes of views (mixed for pseudo views).
    ///
    /// # Shapes
    /// - returns `[views.len(), audio_dim]`
    fn view_codes(&self, data: &TrainData, views: &[u32]) -> Result<Tensor> {
        let v: Vec<&View> = views.iter().map(|&i| &self.views[i as usize]).collect();
        codes_of_views(&v, |ids| self.audio_codes(data, ids))
    }

    /// Draws the main batch: per picked frame, rays from the mouth, the face and the rest
    /// of the hit pixels in the configured proportions.
    fn draw_batch(&self, rng: &mut ChaCha8Rng) -> Vec<BeamRef> {
        let t = &self.cfg.train;
        let usable = |recorded: bool| -> Vec<usize> {
            (0..self.beams.len())
                .filter(|&f| self.views[f].recorded == recorded && !self.beams[f].pixels.is_empty())
                .collect()
        };
        let (real, pseudo) = (usable(true), usable(false));
        if real.is_empty() {
            return Vec::new();
        }
        let n_frames = t.frames_per_batch.max(1);
        let n_pseudo = if pseudo.is_empty() {
            0
        } else {
            ((t.pseudo_fraction.clamp(0.0, 1.0) * n_frames as f32).round() as usize)
                .min(n_frames - 1)
                .min(pseudo.len())
        };
        let n_real = (n_frames - n_pseudo).min(real.len());
        let n_frames = n_real + n_pseudo;
        let mut chosen: Vec<usize> = sample_indices(rng, real.len(), n_real)
            .into_iter()
            .map(|u| real[u])
            .collect();
        chosen.extend(
            sample_indices(rng, pseudo.len(), n_pseudo)
                .into_iter()
                .map(|u| pseudo[u]),
        );
        let mut batch = Vec::with_capacity(t.batch_rays);
        for (slot, &fi) in chosen.iter().enumerate() {
            let fb = &self.beams[fi];
            let count = t.batch_rays / n_frames + usize::from(slot < t.batch_rays % n_frames);
            let n_mouth = if fb.mouth.is_empty() {
                0
            } else {
                (t.mouth_fraction.clamp(0.0, 1.0) * count as f32).round() as usize
            };
            let n_face = if fb.face.is_empty() {
                0
            } else {
                ((t.face_fraction.clamp(0.0, 1.0) * count as f32).round() as usize)
                    .saturating_sub(n_mouth)
            };
            let n_mouth = n_mouth.min(count);
            let n_face = n_face.min(count - n_mouth);
            let n_rest = count - n_mouth - n_face;
            // `face` and `other` split a non-empty frame's pixels, so one of them has some.
            let rest = if fb.other.is_empty() {
                &fb.face
            } else {
                &fb.other
            };
            for (list, n) in [(&fb.mouth, n_mouth), (&fb.face, n_face), (rest, n_rest)] {
                for _ in 0..n {
                    batch.push(BeamRef {
                        frame: fi as u32,
                        pixel: list[rng.random_range(0..list.len())],
                    });
                }
            }
        }
        batch
    }

    /// One training step on a main batch and, with the pool on and filled, a pool batch
    /// whose audio codes are detached: the pool trains the light field only.
    pub fn train_step(&mut self, data: &TrainData) -> Result<StudentStep> {
        let t = self.cfg.train.clone();
        let mut rng = ChaCha8Rng::seed_from_u64(t.seed);
        rng.set_stream(self.step as u64 + 1);
        let main = self.draw_batch(&mut rng);
        if main.is_empty() {
            return Err(Error::Config(
                "no training pixel's ray hits the head's bounds".into(),
            ));
        }
        let (drawn, pool_refs) = if t.pool {
            let n_pool = (t.hard_ratio.clamp(0.0, 1.0) * t.batch_rays as f64).round() as usize;
            let drawn = self.pool.draw(n_pool, &mut rng);
            let refs: Vec<BeamRef> = drawn
                .iter()
                .map(|&i| BeamRef {
                    frame: self.pool.entries[i].frame,
                    pixel: self.pool.entries[i].pixel,
                })
                .collect();
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
        self.step += 1;
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
        let mut rng = ChaCha8Rng::seed_from_u64(self.cfg.train.seed ^ 0x9e37_79b9);
        rng.set_stream(self.step as u64 + 1);
        let drawn = self.pool.draw(n, &mut rng);
        if drawn.is_empty() {
            return Ok(None);
        }
        let refs: Vec<BeamRef> = drawn
            .iter()
            .map(|&i| BeamRef {
                frame: self.pool.entries[i].frame,
                pixel: self.pool.entries[i].pixel,
            })
            .collect();
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
        let ds = &data.dataset;
        let t = &self.cfg.train;
        let m = self.cfg.model.segments;
        let distill = t.distill;
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
        let n = all.len();
        let mut rays = Rays::with_capacity(n);
        let mut gt = Vec::with_capacity(3 * n);
        let mut tgt = Vec::with_capacity(if distill { 3 * m * n } else { 0 });
        let mut row_of_ray = Vec::with_capacity(n);
        for (b, detached) in &all {
            let fi = b.frame as usize;
            let view = &self.views[fi];
            let (i, j) = self.beams[fi].pixels[b.pixel as usize];
            let (o, d) = view.camera.ray(i as f32, j as f32);
            rays.push(o, d);
            let segs = if distill {
                let p = b.pixel as usize;
                let segs = &self.targets[fi][3 * m * p..3 * m * (p + 1)];
                tgt.extend_from_slice(segs);
                segs
            } else {
                &[]
            };
            if view.recorded {
                gt.extend_from_slice(&data.images[fi].get(i, j));
            } else {
                // A pseudo view has no image: its pixel is the teacher's (Eq. 7).
                let mut pixel = [0.0f32; 3];
                for seg in segs.chunks_exact(3) {
                    for (p, v) in pixel.iter_mut().zip(seg) {
                        *p += v;
                    }
                }
                gt.extend_from_slice(&pixel);
            }
            let slot = slot_of[&(b.frame, *detached)];
            row_of_ray.push(if *detached {
                n_main_frames + slot
            } else {
                slot
            });
        }
        let dev = Device::Cpu;
        let codes = table.index_select(&Tensor::from_vec(row_of_ray, n, &dev)?, 0)?;
        let spec = &self.cfg.model.beam;
        let beams = encode_beams_parallel(&rays, ds.near, ds.far, spec, jitter_seed);
        let beams = Tensor::from_vec(beams, (n, spec.encoded_len()), &dev)?;
        let (segments, pixels) = self.student.mlp.forward_fused(&beams, &codes, update)?;
        let gt = Tensor::from_vec(gt, (n, 3), &dev)?;
        let pixel_sq = (&pixels - &gt)?.sqr()?.sum(D::Minus1)?; // [n]
        let mut per_ray = (pixel_sq.clone() / 3.0)?;
        if distill {
            let tgt = Tensor::from_vec(tgt, (n, m, 3), &dev)?;
            let seg_sq = (&segments - &tgt)?.sqr()?.sum((1, 2))?;
            per_ray = (per_ray + (seg_sq * (t.lambda / 3.0))?)?;
        }
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

    /// Renders a whole frame (any split): the rays that meet the head's bounds
    /// ([`head_rays`]) go through the student, the other pixels are the background.
    pub fn render_frame(&self, data: &TrainData, frame: &Frame) -> Result<ImageRgb> {
        let ds = &data.dataset;
        let code = self.audio_codes(data, &[frame.aud_id])?;
        self.render_view(&ds.camera(frame), &ds.background, &code, data)
    }

    /// The image seen by `camera` with one audio code: the student's pixel where the ray
    /// meets the head's bounds, `background` elsewhere.
    ///
    /// # Shapes
    /// - `code`: `[1, audio_dim]`; `background` is the camera's image size
    pub fn render_view(
        &self,
        camera: &Camera,
        background: &ImageRgb,
        code: &Tensor,
        data: &TrainData,
    ) -> Result<ImageRgb> {
        let ds = &data.dataset;
        let head = head_rays(camera, &data.bounds, ds.near, ds.far);
        let mut image = background.clone();
        let spec = &self.cfg.model.beam;
        for (c, chunk) in head.pixels.chunks(RENDER_CHUNK).enumerate() {
            let lo = c * RENDER_CHUNK;
            let sub = Rays {
                origins: head.rays.origins[3 * lo..3 * (lo + chunk.len())].to_vec(),
                directions: head.rays.directions[3 * lo..3 * (lo + chunk.len())].to_vec(),
            };
            let beams = encode_beams_parallel(&sub, ds.near, ds.far, spec, None);
            let beams = Tensor::from_vec(beams, (chunk.len(), spec.encoded_len()), &Device::Cpu)?;
            let codes = code
                .broadcast_as((chunk.len(), code.dim(1)?))?
                .contiguous()?;
            let (_, pixels) = self.student.mlp.forward_fused(&beams, &codes, false)?;
            let pixels: Vec<f32> = pixels.flatten_all()?.to_vec1()?;
            for (k, &p) in chunk.iter().enumerate() {
                image.data[3 * p..3 * p + 3].copy_from_slice(&pixels[3 * k..3 * k + 3]);
            }
        }
        Ok(image)
    }

    /// Renders `n` validation frames spread evenly over the split and scores them.
    pub fn validate(&self, data: &TrainData, n: usize) -> Result<Scores> {
        validate_frames(data, n, &|f| self.render_frame(data, f))
    }

    /// Writes the checkpoint: config, pool, optimizer state and weights.
    pub fn save(&self) -> Result<()> {
        std::fs::create_dir_all(&self.dir).map_err(|e| Error::io(&self.dir, e))?;
        save_json(&self.dir.join(CONFIG_FILE), &self.cfg)?;
        save_pool(&self.dir.join(POOL_FILE), &self.pool, self.step)?;
        let t = &self.cfg.train;
        let title = format!(
            "student {}x{}, {} rays/step{}{}",
            self.cfg.model.depth,
            self.cfg.model.width,
            t.batch_rays,
            if t.distill {
                ", distilled"
            } else {
                ", pixels only"
            },
            if t.pool { ", beam pool" } else { "" }
        );
        save_checkpoint(&CheckpointParts {
            dir: &self.dir,
            kind: "student",
            step: self.step,
            elapsed: self.elapsed(),
            varmap: &self.varmap,
            adam: &self.adam,
            title: &title,
        })
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

impl TrainingRun for StudentRun {
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
        StudentRun::elapsed(self)
    }

    fn learning_rate(&self) -> f64 {
        StudentRun::learning_rate(self)
    }

    fn train_step(&mut self, data: &TrainData) -> Result<(f64, f64)> {
        let s = StudentRun::train_step(self, data)?;
        Ok((s.loss, s.psnr))
    }

    fn validate(&self, data: &TrainData, n: usize) -> Result<Scores> {
        StudentRun::validate(self, data, n)
    }

    fn save(&self) -> Result<()> {
        StudentRun::save(self)
    }
}

/// A fingerprint of the views (poses, audio and mixing weights), stored with the cached
/// targets so that a cache made for other views is never used (FNV-1a over their bits).
fn views_fingerprint(views: &[View]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |v: u64| {
        for b in v.to_le_bytes() {
            h = (h ^ b as u64).wrapping_mul(0x0100_0000_01b3);
        }
    };
    for v in views {
        v.camera
            .c2w
            .to_cols_array()
            .iter()
            .for_each(|x| eat(x.to_bits() as u64));
        eat(v.audio.0 as u64);
        eat(v.audio.1 as u64);
        eat(v.weight.to_bits() as u64);
    }
    format!("{h:016x}")
}

fn save_targets(
    path: &Path,
    targets: &[Vec<f32>],
    m: usize,
    teacher_step: usize,
    views: &str,
) -> Result<()> {
    let mut tensors = HashMap::new();
    for (f, t) in targets.iter().enumerate() {
        let rows = t.len() / (3 * m);
        tensors.insert(
            format!("frame.{f}"),
            Tensor::from_slice(t, (rows, m, 3), &Device::Cpu)?,
        );
    }
    let meta = [
        ("teacher_step".to_string(), teacher_step.to_string()),
        ("segments".to_string(), m.to_string()),
        ("frames".to_string(), targets.len().to_string()),
        ("views".to_string(), views.to_string()),
    ]
    .into_iter()
    .collect();
    save_tensors(path, &tensors, meta)
}

/// The cached targets when they fit the views, `m` and (when known) the teacher's step.
fn load_targets(
    path: &Path,
    beams: &[FrameBeams],
    m: usize,
    teacher_step: Option<usize>,
    views: &str,
) -> Result<Option<Vec<Vec<f32>>>> {
    let (tensors, meta) = load_tensors(path)?;
    let get = |k: &str| meta.get(k).and_then(|v| v.parse::<usize>().ok());
    let fits = get("segments") == Some(m)
        && get("frames") == Some(beams.len())
        && meta.get("views").map(String::as_str) == Some(views)
        && teacher_step.is_none_or(|s| get("teacher_step") == Some(s));
    if !fits {
        return Ok(None);
    }
    let mut out = Vec::with_capacity(beams.len());
    for (f, fb) in beams.iter().enumerate() {
        let Some(t) = tensors.get(&format!("frame.{f}")) else {
            return Ok(None);
        };
        if t.dims() != [fb.pixels.len(), m, 3] {
            return Ok(None);
        }
        out.push(t.flatten_all()?.to_vec1()?);
    }
    Ok(Some(out))
}

fn save_pool(path: &Path, pool: &BeamPool, step: usize) -> Result<()> {
    let dev = Device::Cpu;
    let n = pool.entries.len();
    let frames: Vec<u32> = pool.entries.iter().map(|e| e.frame).collect();
    let pixels: Vec<u32> = pool.entries.iter().map(|e| e.pixel).collect();
    let losses: Vec<f32> = pool.entries.iter().map(|e| e.loss).collect();
    let tensors = [
        ("frame".to_string(), Tensor::from_vec(frames, n, &dev)?),
        ("pixel".to_string(), Tensor::from_vec(pixels, n, &dev)?),
        ("loss".to_string(), Tensor::from_vec(losses, n, &dev)?),
    ]
    .into_iter()
    .collect();
    let meta = [("step".to_string(), step.to_string())]
        .into_iter()
        .collect();
    save_tensors(path, &tensors, meta)
}

fn load_pool(path: &Path, capacity: usize, step: usize) -> Result<BeamPool> {
    let (tensors, meta) = load_tensors(path)?;
    let pool_step = step_of(path, &meta)?;
    if pool_step != step {
        return Err(Error::invalid(
            path,
            format!("is from step {pool_step}, the weights from step {step}"),
        ));
    }
    let get = |k: &str| {
        tensors
            .get(k)
            .ok_or_else(|| Error::invalid(path, format!("lacks `{k}`")))
    };
    let frames: Vec<u32> = get("frame")?.to_vec1()?;
    let pixels: Vec<u32> = get("pixel")?.to_vec1()?;
    let losses: Vec<f32> = get("loss")?.to_vec1()?;
    let mut pool = BeamPool::new(capacity);
    pool.entries = frames
        .into_iter()
        .zip(pixels)
        .zip(losses)
        .map(|((frame, pixel), loss)| PoolEntry { frame, pixel, loss })
        .collect();
    Ok(pool)
}
