//! The student's distillation job: a new student from a shape and training switches or a
//! configuration file, or a resumed one; the teacher's targets are made (or read from their
//! cache) before the first step.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use nldf_core::dataset::AudioChoice;
use nldf_core::run_files::{STUDENT_FILES, has_checkpoint, teacher_dir};

use crate::error::{Error, Result};
use crate::job::{JobEvent, OnEvent, check_resume, load_data, train_stage, wrote};
use crate::networks::student::StudentConfig;
use crate::trainers::config::{StudentRunConfig, check_config, read_config};
use crate::trainers::data::TrainData;
use crate::trainers::scores::Scores;
use crate::trainers::student_trainer::{RECORDED_TARGETS_PART, StudentRun};
use crate::trainers::teacher_trainer::TeacherModel;
use crate::trainers::timing::Timing;

/// Where a new student's configuration comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum StudentSource {
    /// A network shape with the default training settings and these switches.
    Settings {
        model: Box<StudentConfig>,
        /// Distil from the teacher (Eq. 9); off: pixels only.
        distill: bool,
        /// Train the active beam pool.
        pool: bool,
        /// The pseudo views, where they differ from the defaults.
        pseudo: PseudoSettings,
    },
    /// A `{"model": ..., "train": ...}` file, read strictly.
    File(PathBuf),
    /// A configuration made in code (the demo's recipe). Everything a run is built from
    /// (the optimizer's groups, the pool's size) is set before the run exists, so the
    /// run's `config.json` trains the same student again.
    Config(Box<StudentRunConfig>),
}

impl StudentSource {
    /// The configuration this source gives, before a job's step count is applied, and
    /// the file it was read from.
    pub fn config(&self) -> Result<(StudentRunConfig, Option<&Path>)> {
        Ok(match self {
            StudentSource::File(path) => (read_config::<StudentRunConfig>(path)?, Some(path)),
            StudentSource::Settings {
                model,
                distill,
                pool,
                pseudo,
            } => {
                let mut cfg = StudentRunConfig {
                    model: (**model).clone(),
                    ..StudentRunConfig::default()
                };
                cfg.train.distill = *distill;
                cfg.train.pool = *pool;
                pseudo.apply(&mut cfg.train);
                (cfg, None)
            }
            StudentSource::Config(cfg) => ((**cfg).clone(), None),
        })
    }
}

/// Pseudo-view settings that replace [`StudentTrainConfig`]'s defaults where given.
///
/// [`StudentTrainConfig`]: crate::trainers::config::StudentTrainConfig
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PseudoSettings {
    /// Pseudo views the teacher renders.
    pub frames: Option<usize>,
    /// Their pose range, a factor of the recorded yaw and pitch range.
    pub pose_range: Option<f32>,
    /// Hit pixels rendered per pseudo view (0: all).
    pub rays: Option<usize>,
}

impl PseudoSettings {
    /// Writes the given settings into `train`.
    pub fn apply(&self, train: &mut crate::trainers::config::StudentTrainConfig) {
        if let Some(n) = self.frames {
            train.pseudo_frames = n;
        }
        if let Some(r) = self.pose_range {
            train.pose_range = r;
        }
        if let Some(n) = self.rays {
            train.pseudo_rays = n;
        }
    }
}

/// What `nldf train student` was asked to do.
#[derive(Debug, Clone, PartialEq)]
pub struct StudentJob {
    /// The dataset folder the teacher was trained on.
    pub data: PathBuf,
    /// The run folder; its teacher is `RUN/teacher`.
    pub run: PathBuf,
    /// The student's folder name in the run.
    pub name: String,
    /// The configuration of a new student (ignored when resuming).
    pub source: StudentSource,
    /// Training steps (a new run's learning rate decays over them).
    pub iters: Option<usize>,
    /// Wall-clock budget in minutes, teacher targets included.
    pub minutes: Option<f64>,
    /// Continue the checkpoint in `RUN/<name>`.
    pub resume: bool,
}

/// A checked student job: data loaded, teacher opened, run created or opened.
pub struct StudentPlan {
    /// The run, created or opened.
    pub run: StudentRun,
    /// The dataset with the teacher's audio features, its training frames decoded.
    pub data: TrainData,
    /// The teacher to distil from, when the run folder has one.
    pub teacher: Option<TeacherModel>,
}

impl StudentJob {
    /// The student's folder.
    pub fn dir(&self) -> PathBuf {
        self.run.join(&self.name)
    }

    /// Checks the configuration, the run folder and the teacher, loads the data and
    /// creates (or opens) the run; nothing is trained yet.
    pub fn plan(&self, on_event: OnEvent) -> Result<StudentPlan> {
        let dir = self.dir();
        let teacher_dir = teacher_dir(&self.run);
        check_resume(&dir, "student", self.resume)?;
        let teacher = if has_checkpoint(&teacher_dir) {
            Some(TeacherModel::open(&teacher_dir)?)
        } else {
            None
        };
        // The teacher's audio features, else a resumed student's own.
        let teachers_audio = teacher
            .as_ref()
            .map(|t| AudioChoice::Matching(t.cfg.model.audio.features.clone()));
        let (mut run, data) = if self.resume {
            let mut run = StudentRun::open(&dir)?;
            if let Some(n) = self.iters {
                run.model.cfg.train.iters = n;
            }
            let own = AudioChoice::Matching(run.model.cfg.model.audio.features.clone());
            let data = load_data(&self.data, &teachers_audio.unwrap_or(own), on_event)?;
            on_event(&JobEvent::Note(format!(
                "resuming at step {}",
                run.model.step
            )));
            (run, data)
        } else {
            let cfg = self.new_config()?;
            if cfg.train.distill && teacher.is_none() {
                return Err(Error::Config(format!(
                    "{} holds no teacher to distil from; train one with `nldf train \
                     teacher --run {}` or pass --no-distill",
                    teacher_dir.display(),
                    self.run.display()
                )));
            }
            let audio = teachers_audio.unwrap_or(AudioChoice::Auto);
            let data = load_data(&self.data, &audio, on_event)?;
            let run = StudentRun::create(&dir, cfg, &data, teacher.as_ref())?;
            (run, data)
        };
        if let Some(m) = self.minutes {
            run.model.cfg.train.time_budget_s = m * 60.0;
        }
        Ok(StudentPlan { run, data, teacher })
    }

    /// The checked configuration of a new student.
    fn new_config(&self) -> Result<StudentRunConfig> {
        let (mut cfg, file) = self.source.config()?;
        if let Some(n) = self.iters {
            cfg.train.iters = n;
            cfg.train.lr_decay_steps = n;
        }
        check_config(&cfg, file)?;
        Ok(cfg)
    }
}

impl StudentPlan {
    /// Makes the views and the teacher's targets, then trains until the schedule, the
    /// budget or `stop` ends it; lists the files written.
    pub fn run(mut self, stop: &AtomicBool, on_event: OnEvent) -> Result<Option<Scores>> {
        let started = std::time::Instant::now();
        self.run
            .prepare_deferred(&self.data, self.teacher.take(), &mut |done, total| {
                on_event(&JobEvent::Progress {
                    what: "teacher targets".into(),
                    done,
                    total,
                })
            })?;
        let mut before = Timing::default();
        if self.run.model.cfg.train.distill {
            let n = self.run.views.iter().filter(|v| v.recorded).count();
            before.add(RECORDED_TARGETS_PART, started.elapsed().as_secs_f64(), n);
        }
        let pending = self.run.pending_pseudo_views();
        if pending > 0 {
            on_event(&JobEvent::Note(format!(
                "the teacher renders {pending} pseudo views, {} before each step, while the \
                 student trains",
                self.run.model.cfg.train.pseudo_per_step
            )));
        }
        let scores = train_stage(
            "student",
            &before,
            &mut self.run,
            &self.data,
            stop,
            on_event,
        )?;
        on_event(&wrote(&self.run.model.dir, STUDENT_FILES));
        Ok(scores)
    }
}
