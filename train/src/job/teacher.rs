//! The teacher's training job: a new run from a preset or a configuration file, or a
//! resumed one, checked before any step is taken.

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

use nldf_core::dataset::AudioChoice;
use nldf_core::run_files::{TEACHER_FILES, teacher_dir};

use crate::error::Result;
use crate::job::{JobEvent, OnEvent, check_resume, load_data, train_stage, wrote};
use crate::trainers::config::{TeacherConfig, TeacherRunConfig, check_config, read_config};
use crate::trainers::data::TrainData;
use crate::trainers::scores::Scores;
use crate::trainers::teacher_trainer::TeacherRun;

/// Where a new teacher's configuration comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum TeacherSource {
    /// A preset network with the default training settings.
    Preset(Box<TeacherConfig>),
    /// A `{"model": ..., "train": ...}` file, read strictly.
    File(PathBuf),
}

/// What `nldf train teacher` was asked to do.
#[derive(Debug, Clone, PartialEq)]
pub struct TeacherJob {
    /// The dataset folder.
    pub data: PathBuf,
    /// The run folder; the teacher goes to `RUN/teacher`.
    pub run: PathBuf,
    /// The configuration of a new run (ignored when resuming).
    pub source: TeacherSource,
    /// Training steps, replacing the configuration's.
    pub iters: Option<usize>,
    /// Continue the checkpoint in `RUN/teacher`.
    pub resume: bool,
    /// Which audio features a new run reads.
    pub audio: AudioChoice,
    /// Wall-clock budget in seconds, replacing the configuration's.
    pub budget_s: Option<f64>,
}

/// A checked teacher job: the data is loaded and the run created or opened.
pub struct TeacherPlan {
    /// The run, created or opened.
    pub run: TeacherRun,
    /// The dataset with the run's audio features, its training frames decoded.
    pub data: TrainData,
}

impl TeacherJob {
    /// Checks the configuration and the run folder, loads the data and creates (or opens)
    /// the run; nothing is trained yet.
    pub fn plan(&self, on_event: OnEvent) -> Result<TeacherPlan> {
        let dir = teacher_dir(&self.run);
        check_resume(&dir, "teacher", self.resume)?;
        let (mut run, data) = if self.resume {
            // The checkpoint's config says which audio features the run reads.
            let mut run = TeacherRun::open(&dir)?;
            if let Some(n) = self.iters {
                run.model.cfg.train.iters = n;
            }
            let audio = AudioChoice::Matching(run.model.cfg.model.audio.features.clone());
            let data = load_data(&self.data, &audio, on_event)?;
            on_event(&JobEvent::Note(format!(
                "resuming at step {}",
                run.model.step
            )));
            (run, data)
        } else {
            let cfg = self.new_config()?;
            let data = load_data(&self.data, &self.audio, on_event)?;
            (TeacherRun::create(&dir, cfg, &data)?, data)
        };
        if let Some(b) = self.budget_s {
            run.model.cfg.train.time_budget_s = b;
        }
        Ok(TeacherPlan { run, data })
    }

    /// The checked configuration of a new run.
    fn new_config(&self) -> Result<TeacherRunConfig> {
        let (mut cfg, file) = match &self.source {
            TeacherSource::File(path) => (read_config::<TeacherRunConfig>(path)?, Some(path)),
            TeacherSource::Preset(model) => (
                TeacherRunConfig {
                    model: (**model).clone(),
                    ..TeacherRunConfig::default()
                },
                None,
            ),
        };
        if let Some(n) = self.iters {
            cfg.train.iters = n;
        }
        check_config(&cfg, file.map(PathBuf::as_path))?;
        Ok(cfg)
    }
}

impl TeacherPlan {
    /// Trains until the schedule, the budget or `stop` ends it; lists the files written.
    pub fn run(mut self, stop: &AtomicBool, on_event: OnEvent) -> Result<Option<Scores>> {
        let scores = train_stage(
            "teacher",
            &crate::trainers::timing::Timing::default(),
            &mut self.run,
            &self.data,
            stop,
            on_event,
        )?;
        on_event(&wrote(&self.run.model.dir, TEACHER_FILES));
        Ok(scores)
    }
}
