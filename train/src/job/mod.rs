//! Training jobs: what a user asks for (train a teacher, distil a student, evaluate a run,
//! run the ablation), checked and loaded into a plan before any work starts, then run with
//! progress events, as nldf-infer's `VideoJob -> VideoPlan` is. The command line only turns
//! flags into jobs and events into progress bars; the tests run the same jobs end to end.
//! The whole demo, which also exports, is nldf-pipeline's job; its recipe is [`recipe`].

pub mod ablation;
pub mod curves;
pub mod eval;
pub mod lookahead;
pub mod posed;
pub mod recipe;
pub mod student;
pub mod teacher;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use nldf_core::dataset::AudioChoice;
use nldf_core::run_files::has_checkpoint;

use crate::error::{Error, Result};
use crate::trainers::data::TrainData;
use crate::trainers::run_loop::Event;
use crate::trainers::run_loop::TrainingRun;
use crate::trainers::scores::Scores;
use crate::trainers::timing::{TIMING_FILE, Timing};

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

/// Loads the dataset at `root` for training (its training frames decoded) with the audio
/// features `audio` says, and notes which features it read.
pub(crate) fn load_data(root: &Path, audio: &AudioChoice, on_event: OnEvent) -> Result<TrainData> {
    on_event(&JobEvent::Note(format!("loading {}", root.display())));
    let data = TrainData::open_with(root, true, audio)?;
    on_event(&audio_note(&data));
    on_event(&mouth_note(&data));
    Ok(data)
}

/// The note saying which audio features a stage read.
pub(crate) fn audio_note(data: &TrainData) -> JobEvent {
    JobEvent::Note(format!(
        "audio features: {} from {}",
        data.dataset.audio_source.describe(),
        data.dataset.audio_file.display()
    ))
}

/// The note saying where the mouth region (mouth rays, mouth PSNR) comes from, or that it
/// is unknown.
pub(crate) fn mouth_note(data: &TrainData) -> JobEvent {
    JobEvent::Note(format!(
        "mouth region: {}",
        data.dataset.mouth_source().describe()
    ))
}

/// The event listing `files` of `dir`.
pub(crate) fn wrote(dir: &Path, files: &[&str]) -> JobEvent {
    JobEvent::Wrote {
        dir: dir.to_path_buf(),
        files: files.iter().map(|f| dir.join(f)).collect(),
    }
}

/// Refuses a new run over a checkpoint, and a resume without one.
pub(crate) fn check_resume(dir: &std::path::Path, what: &str, resume: bool) -> Result<()> {
    let exists = has_checkpoint(dir);
    if exists && !resume {
        return Err(Error::Config(format!(
            "{} already holds a {what}; pass --resume to continue it or choose another --run",
            dir.display()
        )));
    }
    if resume && !exists {
        return Err(Error::Config(format!(
            "{} holds no {what} checkpoint to resume",
            dir.display()
        )));
    }
    Ok(())
}

/// Runs the training loop of `run` as stage `stage`, forwarding its events.
/// The seconds of the stage's loop, with `before` (the work that preceded it, such as the
/// teacher's targets), are added to `timing.json` in the run's folder and printed.
pub(crate) fn train_stage(
    stage: &str,
    before: &Timing,
    run: &mut dyn TrainingRun,
    data: &TrainData,
    stop: &AtomicBool,
    on_event: OnEvent,
) -> Result<Option<Scores>> {
    on_event(&JobEvent::TrainingStarts {
        stage: stage.to_string(),
        step: run.step(),
        iters: run.schedule().iters,
    });
    let dir = run.dir().to_path_buf();
    let mut timing = Timing::open(&dir)?;
    timing.absorb("", before);
    let result =
        crate::trainers::run_loop::train_loop_timed(run, data, stop, &mut timing, &mut |event| {
            on_event(&JobEvent::Training {
                stage: stage.to_string(),
                event: event.clone(),
            })
        });
    // Kept whatever ended the loop: an interrupted or failed stage's time was spent too.
    timing.save(&dir)?;
    on_event(&JobEvent::Note(format!(
        "{stage} time, all sessions of this run ({}):",
        dir.join(TIMING_FILE).display()
    )));
    for line in timing.lines() {
        on_event(&JobEvent::Note(format!("  {line}")));
    }
    let scores = result?;
    let t = run.schedule();
    if t.time_cap_s > 0.0 && run.step() < t.iters && run.elapsed() >= t.time_cap_s {
        on_event(&JobEvent::Note(format!(
            "the {stage}'s wall-clock cap of {:.1} min cut it short at step {} of {}: this \
             machine is slower than the recipe was sized for, and its scores will be lower",
            t.time_cap_s / 60.0,
            run.step(),
            t.iters
        )));
    }
    on_event(&JobEvent::TrainingEnds {
        stage: stage.to_string(),
        step: run.step(),
        interrupted: stop.load(Ordering::Relaxed),
        scores,
    });
    Ok(scores)
}
