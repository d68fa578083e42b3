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

use candle_core::{Device, Tensor};
use candle_nn::VarMap;
use nldf_core::beam::{BeamAnchor, encode_beams_parallel};
use nldf_core::camera::Camera;
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

use crate::adam::{Adam, AdamParams};
use crate::checkpoint::save_json;
use crate::checkpoint::{CheckpointParts, Clock, open_checkpoint, save_checkpoint};
use crate::config::{RunConfig, StudentRunConfig, read_config};
use crate::data::TrainData;
use crate::error::{Error, Result};
use crate::loss::{RayLosses, TeacherTargets, distillation_loss};
use crate::nn::{new_varmap, scaled_vars, sorted_vars};
use crate::pool::{BeamPool, PoolEntry};
use crate::pool::{load_pool, save_pool};
use crate::run_loop::{TrainingRun, finite_loss, run_fields};
use crate::scores::{Scores, score_validation_frames};
use crate::student::{Student, student};
use crate::targets::{TargetLayout, load_targets, save_targets, teacher_targets, view_targets};
use crate::teacher_trainer::TeacherModel;
use crate::views::{
    FrameBeams, View, frame_beams, mouth_surface_points, thin_beams, thin_pseudo_beams,
    training_views, views_fingerprint,
};

/// Rays per forward pass when rendering.
const RENDER_CHUNK: usize = 8192;

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

/// A trained student, for rendering: its folder, configuration and weights, and the step
/// they were saved at. [`StudentModel::open`] reads nothing of the training state (the
/// optimizer's moments, the beam pool), so a model renders whether or not its run can
/// resume.
pub struct StudentModel {
    pub dir: PathBuf,
    pub cfg: StudentRunConfig,
    pub varmap: VarMap,
    pub student: Student,
    /// Steps done.
    pub step: usize,
    /// Training seconds the checkpoint it was opened from records, across resumes (0 for
    /// a new model; a run's own clock is its `elapsed()`).
    pub trained_s: f64,
}

impl StudentModel {
    /// Loads the trained student in `dir`: its `config.json` and weights.
    pub fn open(dir: &Path) -> Result<StudentModel> {
        let mut model = Self::build(dir, read_config(&dir.join(CONFIG_FILE))?)?;
        let (step, clock) = open_checkpoint(dir, &model.varmap, None)?;
        (model.step, model.trained_s) = (step, clock.elapsed());
        Ok(model)
    }

    /// The network of `cfg` at step 0, weights as the variable builder made them.
    fn build(dir: &Path, cfg: StudentRunConfig) -> Result<StudentModel> {
        cfg.check()?;
        let (varmap, vb) = new_varmap();
        let student = student(&cfg.model, vb)?;
        Ok(StudentModel {
            dir: dir.to_path_buf(),
            cfg,
            varmap,
            student,
            step: 0,
            trained_s: 0.0,
        })
    }

    /// Audio codes of frames.
    ///
    /// # Shapes
    /// - returns `[aud_ids.len(), audio_dim]`
    pub fn audio_codes(&self, data: &TrainData, aud_ids: &[usize]) -> Result<Tensor> {
        let windows = data.neighbourhoods(aud_ids, self.cfg.model.audio.att_frames)?;
        Ok(self.student.audio_codes(&windows)?)
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
        let head = head_rays(camera, &data.head_range());
        let mut image = background.clone();
        let spec = &self.cfg.model.beam;
        for (c, chunk) in head.pixels.chunks(RENDER_CHUNK).enumerate() {
            let lo = c * RENDER_CHUNK;
            let sub = head.rays.slice(lo..lo + chunk.len());
            let beams = encode_beams_parallel(&sub, ds.near, ds.far, spec, None);
            let beams = Tensor::from_vec(beams, (chunk.len(), spec.encoded_len()), &Device::Cpu)?;
            let codes = code
                .broadcast_as((chunk.len(), code.dim(1)?))?
                .contiguous()?;
            let out = self.student.mlp.forward_fused(&beams, &codes, false)?;
            let pixels = if self.cfg.model.opacity {
                let bg = background.gather(chunk);
                out.pixels(&Tensor::from_vec(bg, (chunk.len(), 3), &Device::Cpu)?)?
            } else {
                out.colour
            };
            let pixels: Vec<f32> = pixels.flatten_all()?.to_vec1()?;
            image.paint(chunk, &pixels);
        }
        Ok(image)
    }

    /// Renders `n` validation frames spread evenly over the split and scores them.
    pub fn validation_scores(&self, data: &TrainData, n: usize) -> Result<Scores> {
        score_validation_frames(data, n, &|f| self.render_frame(data, f))
    }
}

/// A student being trained: folder, configuration, weights, optimizer, pool and the cached
/// per-frame beams and teacher targets.
pub struct StudentRun {
    pub model: StudentModel,
    adam: Adam,
    clock: Clock,
    pub pool: BeamPool,
    /// The training frames, then the pseudo views (set by [`StudentRun::prepare`]).
    pub views: Vec<View>,
    /// Hit pixels per view.
    pub beams: Vec<FrameBeams>,
    /// Teacher segment colours per view, aligned with `beams` (distillation); empty for a
    /// pseudo view the teacher has not rendered yet.
    pub targets: Vec<Vec<f32>>,
    /// The teacher that renders the pseudo views' targets between steps, and the next
    /// view to render ([`StudentRun::prepare_deferred`]).
    pending: Option<(TeacherModel, usize)>,
    /// Seconds the last step spent rendering pseudo views' targets, and how many.
    pseudo_time: (f64, usize),
    /// The moving average of the weights (`ema_decay`), in `sorted_vars` order, once the
    /// learning rate decays.
    average: Option<Vec<Tensor>>,
}

/// The timing part of the teacher rendering recorded frames' targets.
pub const RECORDED_TARGETS_PART: &str = "teacher targets: recorded frames";
/// The timing part of the teacher rendering pseudo views' targets.
pub const PSEUDO_TARGETS_PART: &str = "teacher targets: pseudo views";

impl StudentRun {
    /// A new run in `dir` with seeded weights. The audio feature width comes from the data;
    /// with a teacher, the student's audio encoder starts as the teacher's (same shape and
    /// weights, attention as the teacher last used it).
    pub fn create(
        dir: &Path,
        mut cfg: StudentRunConfig,
        data: &TrainData,
        teacher: Option<&TeacherModel>,
    ) -> Result<StudentRun> {
        cfg.model.audio.set_from(&data.dataset);
        if cfg.model.anchor_beams && cfg.model.beam.anchor.is_none() {
            let c2ws: Vec<_> = data
                .dataset
                .frames(Split::Train)
                .iter()
                .map(|f| f.c2w)
                .collect();
            cfg.model.beam.anchor = BeamAnchor::of_cameras(data.bounds.centre(), &c2ws);
        }
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
        crate::audio_net::init_with_centred_attention(
            &run.model.varmap,
            run.model.cfg.train.seed,
            run.model.cfg.model.audio.att_frames,
        )?;
        if let Some(t) = teacher {
            let theirs = sorted_vars(&t.varmap)?
                .into_iter()
                .collect::<HashMap<String, candle_core::Var>>();
            for (name, var) in sorted_vars(&run.model.varmap)? {
                if name.starts_with("audio.")
                    && let Some(src) = theirs.get(&name)
                {
                    var.set(src.as_tensor())?;
                }
            }
        }
        Ok(run)
    }

    /// Loads the run in `dir` to continue training: config, weights, optimizer state and
    /// pool. To render, [`StudentModel::open`] reads the weights alone.
    pub fn open(dir: &Path) -> Result<StudentRun> {
        let mut run = Self::build(dir, read_config(&dir.join(CONFIG_FILE))?)?;
        let (model, adam) = (&mut run.model, &mut run.adam);
        (model.step, run.clock) = open_checkpoint(dir, &model.varmap, Some(adam))?;
        let pool_path = dir.join(POOL_FILE);
        if pool_path.is_file() {
            run.pool = load_pool(&pool_path, run.pool.capacity, run.model.step)?;
        }
        Ok(run)
    }

    fn build(dir: &Path, cfg: StudentRunConfig) -> Result<StudentRun> {
        let model = StudentModel::build(dir, cfg)?;
        let t = &model.cfg.train;
        let vars = scaled_vars(&model.varmap, &[("audio.", t.audio_lr_scale)])?;
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
            model,
            pool: BeamPool::new(capacity),
            adam,
            clock: Clock::resumed(0.0),
            views: Vec::new(),
            beams: Vec::new(),
            targets: Vec::new(),
            pending: None,
            pseudo_time: (0.0, 0),
            average: None,
        })
    }

    /// Makes the views (training frames and pseudo views), finds their hit pixels and,
    /// when distilling, the teacher's segment colours: read from `targets.safetensors` when
    /// it matches the views and the teacher's step, otherwise computed with `teacher` and
    /// cached. Writes `render.json` and the background beside the checkpoint.
    pub fn prepare(
        &mut self,
        data: &TrainData,
        teacher: Option<&TeacherModel>,
        progress: &mut dyn FnMut(usize, usize),
    ) -> Result<()> {
        if let Some(layout) = self.prepare_cached(data, teacher)? {
            let teacher = teacher.ok_or_else(|| self.no_teacher())?;
            self.targets =
                teacher_targets(teacher, data, &self.views, &self.beams, layout, progress)?;
            self.save_targets(teacher.step)?;
        }
        Ok(())
    }

    /// [`StudentRun::prepare`], except that without a matching cache only the recorded
    /// frames' targets are rendered now: the pseudo views' are rendered
    /// `pseudo_per_step` at a time before each training step, so the student starts at
    /// once and learns from each pseudo view as soon as it exists. The cache is written
    /// once all are done.
    pub fn prepare_deferred(
        &mut self,
        data: &TrainData,
        teacher: Option<TeacherModel>,
        progress: &mut dyn FnMut(usize, usize),
    ) -> Result<()> {
        let Some(layout) = self.prepare_cached(data, teacher.as_ref())? else {
            return Ok(());
        };
        let teacher = teacher.ok_or_else(|| self.no_teacher())?;
        let n_recorded = self.views.iter().filter(|v| v.recorded).count();
        self.targets = teacher_targets(
            &teacher,
            data,
            &self.views[..n_recorded],
            &self.beams[..n_recorded],
            layout,
            progress,
        )?;
        self.targets.resize(self.views.len(), Vec::new());
        if n_recorded == self.views.len() {
            self.save_targets(teacher.step)?;
        } else {
            self.pending = Some((teacher, n_recorded));
        }
        Ok(())
    }

    /// Pseudo views whose targets are still to be rendered.
    pub fn pending_pseudo_views(&self) -> usize {
        self.pending
            .as_ref()
            .map_or(0, |(_, next)| self.views.len() - next)
    }

    /// What the teacher renders per ray for this student.
    fn target_layout(&self) -> TargetLayout {
        TargetLayout {
            segments: self.model.cfg.model.segments,
            opacity: self.model.cfg.model.opacity,
            anchor: self.model.cfg.model.beam.anchor,
        }
    }

    /// The views, their hit pixels, the render spec and background files, and the cached
    /// targets when they fit; `Some(layout)` when targets must be rendered.
    fn prepare_cached(
        &mut self,
        data: &TrainData,
        teacher: Option<&TeacherModel>,
    ) -> Result<Option<TargetLayout>> {
        let teacher_step = teacher.map(|t| t.step);
        std::fs::create_dir_all(&self.model.dir).map_err(|e| Error::io(&self.model.dir, e))?;
        self.views = training_views(
            data,
            &self.model.cfg.train,
            self.model.cfg.model.beam.anchor.is_some(),
        );
        // Pseudo views find their mouth by projecting the recorded frames' mouth through
        // the teacher's depth.
        let mouth_points = match teacher {
            Some(t)
                if self.views.iter().any(|v| !v.recorded) && self.model.cfg.train.project_mouth =>
            {
                Some(mouth_surface_points(t, data)?)
            }
            _ => None,
        };
        self.beams = frame_beams(data, &self.views, mouth_points.as_deref());
        let t = &self.model.cfg.train;
        thin_pseudo_beams(&self.views, &mut self.beams, t.pseudo_rays, t.seed);
        thin_beams(
            &self.views,
            &mut self.beams,
            t.recorded_rays,
            true,
            t.seed ^ 0x7ec0_4de5,
        );
        self.pending = None;
        let spec = RenderSpec::of_dataset(
            &data.dataset,
            data.bounds,
            self.model.cfg.model.audio.att_frames,
        );
        spec.save(&self.model.dir.join(RENDER_SPEC_FILE))?;
        data.dataset
            .background
            .save_png(&self.model.dir.join(BACKGROUND_FILE))?;
        if !self.model.cfg.train.distill {
            return Ok(None);
        }
        let layout = self.target_layout();
        let path = self.model.dir.join(TARGETS_FILE);
        let fingerprint = views_fingerprint(&self.views, &self.beams);
        // Without a teacher at hand, a cache made by any teacher step is used.
        if path.is_file()
            && let Some(cached) =
                load_targets(&path, &self.beams, layout, teacher_step, &fingerprint)?
        {
            self.targets = cached;
            return Ok(None);
        }
        Ok(Some(layout))
    }

    fn no_teacher(&self) -> Error {
        Error::Config(format!(
            "distillation needs the teacher's segment colours: {} is missing and no teacher was given",
            self.model.dir.join(TARGETS_FILE).display()
        ))
    }

    fn save_targets(&self, teacher_step: usize) -> Result<()> {
        save_targets(
            &self.model.dir.join(TARGETS_FILE),
            &self.targets,
            self.target_layout(),
            teacher_step,
            &views_fingerprint(&self.views, &self.beams),
        )
    }

    /// Renders the next `pseudo_per_step` pending pseudo views' targets; writes the cache
    /// once the last is done.
    fn render_pending(&mut self, data: &TrainData) -> Result<()> {
        let Some((teacher, next)) = self.pending.take() else {
            return Ok(());
        };
        let layout = self.target_layout();
        let end = (next + self.model.cfg.train.pseudo_per_step).min(self.views.len());
        let started = std::time::Instant::now();
        for v in next..end {
            self.targets[v] = view_targets(&teacher, data, &self.views[v], &self.beams[v], layout)?;
        }
        self.pseudo_time.0 += started.elapsed().as_secs_f64();
        self.pseudo_time.1 += end - next;
        if end == self.views.len() {
            self.save_targets(teacher.step)
        } else {
            self.pending = Some((teacher, end));
            Ok(())
        }
    }

    /// Training seconds so far, across resumes.
    pub fn elapsed(&self) -> f64 {
        self.clock.elapsed()
    }

    /// The learning rate now ([`StudentTrainConfig::learning_rate`]).
    pub fn learning_rate(&self) -> f64 {
        self.model
            .cfg
            .train
            .learning_rate(self.model.step, self.elapsed())
    }

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

    /// Draws the main batch: per picked frame, rays from the mouth, the face and the rest
    /// of the hit pixels in the configured proportions.
    fn draw_batch(&self, rng: &mut ChaCha8Rng) -> Vec<BeamRef> {
        let t = &self.model.cfg.train;
        let usable = |recorded: bool| -> Vec<usize> {
            (0..self.beams.len())
                .filter(|&f| {
                    self.views[f].recorded == recorded
                        && !self.beams[f].pixels.is_empty()
                        && (recorded || self.targets.get(f).is_some_and(|t| !t.is_empty()))
                })
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

    /// The beams of the pool entries `drawn`.
    fn pool_refs(&self, drawn: &[usize]) -> Vec<BeamRef> {
        drawn
            .iter()
            .map(|&i| BeamRef {
                frame: self.pool.entries[i].frame,
                pixel: self.pool.entries[i].pixel,
            })
            .collect()
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
        let ds = &data.dataset;
        let t = &self.model.cfg.train;
        let m = self.model.cfg.model.segments;
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
        let layout = self.target_layout();
        let width = layout.width();
        let opacity = layout.opacity;
        let floor = self.model.cfg.train.opacity_floor;
        let empty = vec![0.0f32; width];
        let mut rays = Rays::with_capacity(n);
        let mut gt = Vec::with_capacity(3 * n);
        let mut bg = Vec::with_capacity(if opacity { 3 * n } else { 0 });
        let mut tgt = Vec::with_capacity(if distill { 3 * m * n } else { 0 });
        let mut tgt_alpha = Vec::with_capacity(if distill && opacity { n } else { 0 });
        let mut row_of_ray = Vec::with_capacity(n);
        for (b, detached) in &all {
            let fi = b.frame as usize;
            let view = &self.views[fi];
            let (i, j) = self.beams[fi].pixels[b.pixel as usize];
            let (o, d) = view.camera.ray(i as f32, j as f32);
            rays.push(o, d);
            // The background is in screen space: a pseudo view's pixel sees the same one.
            let back = ds.background.get(i, j);
            if opacity {
                bg.extend_from_slice(&back);
            }
            let target = if distill {
                let p = b.pixel as usize;
                let mut target = &self.targets[fi][width * p..width * (p + 1)];
                if opacity && target[3 * m] < floor {
                    // An empty target: no colour, nothing covering the background.
                    target = &empty[..];
                }
                tgt.extend_from_slice(&target[..3 * m]);
                if opacity {
                    tgt_alpha.push(target[3 * m]);
                }
                target
            } else {
                &[]
            };
            if view.recorded {
                gt.extend_from_slice(&data.images[fi].get(i, j));
            } else {
                // A pseudo view has no image: its pixel is the teacher's (Eq. 7), over the
                // background where it has opacity.
                let mut pixel = [0.0f32; 3];
                for seg in target[..3 * m].chunks_exact(3) {
                    for (p, v) in pixel.iter_mut().zip(seg) {
                        *p += v;
                    }
                }
                if opacity {
                    let clear = 1.0 - target[3 * m];
                    for (p, b) in pixel.iter_mut().zip(back) {
                        *p += clear * b;
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
        let spec = &self.model.cfg.model.beam;
        let beams = encode_beams_parallel(&rays, ds.near, ds.far, spec, jitter_seed);
        let beams = Tensor::from_vec(beams, (n, spec.encoded_len()), &dev)?;
        let out = self
            .model
            .student
            .mlp
            .forward_fused(&beams, &codes, update)?;
        let pixels = if opacity {
            out.pixels(&Tensor::from_vec(bg, (n, 3), &dev)?)?
        } else {
            out.colour.clone()
        };
        let gt = Tensor::from_vec(gt, (n, 3), &dev)?;
        let tgt = if distill {
            Some(Tensor::from_vec(tgt, (n, m, 3), &dev)?)
        } else {
            None
        };
        let tgt_alpha = if distill && opacity {
            Some(Tensor::from_vec(tgt_alpha, (n, 1), &dev)?)
        } else {
            None
        };
        let RayLosses { per_ray, pixel_sq } = distillation_loss(
            &pixels,
            &gt,
            &out.segments,
            out.logit.as_ref(),
            tgt.as_ref().map(|segments| TeacherTargets {
                segments,
                opacity: tgt_alpha.as_ref(),
            }),
            t.lambda,
        )?;
        // Mouth rays weigh `mouth_weight` times another ray in the loss (and the pool).
        let per_ray = if t.mouth_weight != 1.0 {
            let w: Vec<f32> = all
                .iter()
                .map(|(b, _)| {
                    let mouth = &self.beams[b.frame as usize].mouth;
                    if mouth.binary_search(&b.pixel).is_ok() {
                        t.mouth_weight
                    } else {
                        1.0
                    }
                })
                .collect();
            (per_ray * Tensor::from_vec(w, n, &dev)?)?
        } else {
            per_ray
        };
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

    /// Writes the checkpoint: config, pool, optimizer state and weights.
    pub fn save(&self) -> Result<()> {
        std::fs::create_dir_all(&self.model.dir).map_err(|e| Error::io(&self.model.dir, e))?;
        save_json(&self.model.dir.join(CONFIG_FILE), &self.model.cfg)?;
        save_pool(&self.model.dir.join(POOL_FILE), &self.pool, self.model.step)?;
        let t = &self.model.cfg.train;
        let title = format!(
            "student {}x{}, {} rays/step{}{}",
            self.model.cfg.model.depth,
            self.model.cfg.model.width,
            t.batch_rays,
            if t.distill {
                ", distilled"
            } else {
                ", pixels only"
            },
            if t.pool { ", beam pool" } else { "" }
        );
        save_checkpoint(&CheckpointParts {
            dir: &self.model.dir,
            kind: "student",
            step: self.model.step,
            elapsed: self.elapsed(),
            varmap: &self.model.varmap,
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
    run_fields!(StudentRun);

    fn train_step(&mut self, data: &TrainData) -> Result<(f64, f64)> {
        let s = StudentRun::train_step(self, data)?;
        Ok((s.loss, s.psnr))
    }

    fn take_side_times(&mut self) -> Vec<(&'static str, f64, usize)> {
        let (seconds, views) = std::mem::take(&mut self.pseudo_time);
        if views == 0 {
            Vec::new()
        } else {
            vec![(PSEUDO_TARGETS_PART, seconds, views)]
        }
    }
}
