//! Training jobs: what a user asks for (train a teacher, distil a student, evaluate a run,
//! run the ablation, the whole demo), checked and loaded into a plan before any work
//! starts, then run with progress events, as nldf-infer's `VideoJob -> VideoPlan` is. The
//! command line only turns flags into jobs and events into progress bars; the tests run
//! the same jobs end to end.

pub mod ablation;
pub mod demo;
pub mod eval;
pub mod student;
pub mod teacher;

use std::path::{Path, PathBuf};

use crate::data::TrainData;
use crate::run_loop::Event;
use crate::scores::Scores;

/// What a job reports as it goes.
#[derive(Debug, Clone, PartialEq)]
pub enum JobEvent {
    /// A stage of the job begins; the line says what it does.
    Stage(String),
    /// A line worth telling the user: which audio features were read, a resume.
    Note(String),
    /// Training of `stage` begins at `step` of `iters`.
    TrainingStarts {
        stage: String,
        step: usize,
        iters: usize,
    },
    /// The training loop's own events.
    Training { stage: String, event: Event },
    /// Training of `stage` ended at `step`: `interrupted` when a stop request ended it,
    /// `scores` the final validation when it ran to the end.
    TrainingEnds {
        stage: String,
        step: usize,
        interrupted: bool,
        scores: Option<Scores>,
    },
    /// Work that counts up: `done` of `total` (teacher targets, evaluation frames).
    Progress {
        what: String,
        done: usize,
        total: usize,
    },
    /// The files a stage wrote.
    Wrote { dir: PathBuf, files: Vec<PathBuf> },
}

/// The receiver of a job's events.
pub type OnEvent<'a> = &'a mut dyn FnMut(&JobEvent);

/// The note saying which audio features a stage read.
pub(crate) fn audio_note(data: &TrainData) -> JobEvent {
    JobEvent::Note(format!(
        "audio features: {} from {}",
        data.dataset.audio_source.describe(),
        data.dataset.audio_file.display()
    ))
}

/// The event listing `files` of `dir`.
pub(crate) fn wrote(dir: &Path, files: &[&str]) -> JobEvent {
    JobEvent::Wrote {
        dir: dir.to_path_buf(),
        files: files.iter().map(|f| dir.join(f)).collect(),
    }
}
