//! The student's trainer (paper sections 3.4-3.5): beams through the pixels whose rays hit
//! the head's bounds, 90 % of them inside `face_rect`; the loss of Eq. 9 (pixel loss plus
//! lambda times the segment loss against the frozen teacher's Eq. 5 colours); the active
//! beam pool trained as an extra batch that reaches the light field only; Adam, `log.csv`,
//! validation, atomic checkpoints and bit-exact resume as for the teacher.
//!
//! The teacher's segment colours are computed once per training pixel and cached in
//! `targets.safetensors`: a 2-core machine renders the teacher at a few thousand rays per
//! second, and training visits every pixel many times.

mod batch;
mod model;
mod prepare;
mod step;

use std::collections::HashMap;
use std::path::Path;

use candle_core::Tensor;
use nldf_core::beam::BeamAnchor;
use nldf_core::dataset::Split;
use nldf_core::run_files::{CONFIG_FILE, POOL_FILE};

pub use self::model::StudentModel;
use crate::error::{Error, Result};
use crate::networks::nn::{scaled_vars, sorted_vars};
use crate::trainers::adam::{Adam, AdamParams};
use crate::trainers::checkpoint::save_json;
use crate::trainers::checkpoint::{CheckpointParts, Clock, open_checkpoint, save_checkpoint};
use crate::trainers::config::{StudentRunConfig, read_config};
use crate::trainers::data::TrainData;
use crate::trainers::pool::BeamPool;
use crate::trainers::pool::{load_pool, save_pool};
use crate::trainers::run_loop::{TrainingRun, run_fields};
use crate::trainers::teacher_trainer::TeacherModel;
use crate::trainers::views::{FrameBeams, View};

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
        if cfg.model.beam.anchor.is_none() {
            let c2ws: Vec<_> = data
                .dataset
                .frames(Split::Train)
                .iter()
                .map(|f| f.c2w)
                .collect();
            let anchor = BeamAnchor::of_cameras(data.bounds.centre(), &c2ws);
            cfg.model.beam.anchor = Some(anchor.ok_or_else(|| {
                Error::Config(format!(
                    "cannot anchor the student's beams: the training cameras of {} have no \
                     finite mean distance to the head's centre",
                    data.dataset.root.display()
                ))
            })?);
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
        crate::networks::audio_net::init_with_centred_attention(
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
