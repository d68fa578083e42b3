//! The training loop every stage shares: steps until the schedule, the time budget or a stop
//! request ends it, with validation, `log.csv`, checkpoints and progress events, stopping
//! at the first non-finite loss or gradient.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use candle_core::{DType, Tensor};

use crate::error::{Error, Result};
use crate::trainers::data::TrainData;
use crate::trainers::scores::Scores;
use crate::trainers::timing::Timing;
use nldf_core::run_files::LOG_FILE;

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
    /// A cap that only stops the run (0: none).
    pub time_cap_s: f64,
}

impl Schedule {
    /// Whether `elapsed` training seconds spend the time budget or reach the cap.
    fn spent(&self, elapsed: f64) -> bool {
        (self.time_budget_s > 0.0 && elapsed >= self.time_budget_s)
            || (self.time_cap_s > 0.0 && elapsed >= self.time_cap_s)
    }
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
    fn validation_scores(&self, data: &TrainData, n: usize) -> Result<Scores>;
    /// Writes the checkpoint.
    fn save(&self) -> Result<()>;
    /// Seconds of the last step that went to work other than the step itself (the
    /// teacher rendering pseudo views' targets between student steps), per named part,
    /// with how many items each did; taken, so each is reported once.
    fn take_side_times(&mut self) -> Vec<(&'static str, f64, usize)> {
        Vec::new()
    }
}

/// Implements the [`TrainingRun`] methods that every run answers from the same fields (its
/// `dir`, `step` and `cfg.train` schedule), from its model's `validation_scores` and from
/// its own `elapsed`, `learning_rate` and `save` methods.
macro_rules! run_fields {
    ($run:ty) => {
        fn dir(&self) -> &std::path::Path {
            &self.model.dir
        }

        fn step(&self) -> usize {
            self.model.step
        }

        fn schedule(&self) -> $crate::trainers::run_loop::Schedule {
            let t = &self.model.cfg.train;
            $crate::trainers::run_loop::Schedule {
                iters: t.iters,
                batch_rays: t.batch_rays,
                log_every: t.log_every,
                val_every: t.val_every,
                val_frames: t.val_frames,
                checkpoint_every: t.checkpoint_every,
                time_budget_s: t.time_budget_s,
                time_cap_s: t.time_cap_s,
            }
        }

        fn elapsed(&self) -> f64 {
            <$run>::elapsed(self)
        }

        fn learning_rate(&self) -> f64 {
            <$run>::learning_rate(self)
        }

        fn validation_scores(
            &self,
            data: &$crate::trainers::data::TrainData,
            n: usize,
        ) -> $crate::Result<$crate::trainers::scores::Scores> {
            self.model.validation_scores(data, n)
        }

        fn save(&self) -> $crate::Result<()> {
            <$run>::save(self)
        }
    };
}
pub(crate) use run_fields;

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
    train_loop_timed(run, data, stop, &mut Timing::default(), on_event)
}

/// The step part of a [`Timing`]: the training steps themselves.
pub const STEPS_PART: &str = "training steps";
/// The validation part of a [`Timing`].
pub const VALIDATION_PART: &str = "validation renders";
/// The checkpoint part of a [`Timing`].
pub const CHECKPOINT_PART: &str = "checkpoints";

/// [`train_loop`], adding the seconds of its steps, validations and checkpoints (and the
/// run's side work, [`TrainingRun::take_side_times`]) to `timing`.
pub fn train_loop_timed(
    run: &mut dyn TrainingRun,
    data: &TrainData,
    stop: &AtomicBool,
    timing: &mut Timing,
    on_event: &mut dyn FnMut(&Event),
) -> Result<Option<Scores>> {
    let dir = run.dir().to_path_buf();
    std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
    let mut log = crate::trainers::log::CsvLog::open(&dir.join(LOG_FILE), run.step())?;
    let t = run.schedule();
    let mut last_val = None;
    let mut saved = (run.step() > 0).then_some(run.step());
    let spent = |run: &dyn TrainingRun| t.spent(run.elapsed());
    // A run resumed with its budget already spent trains no further step.
    while run.step() < t.iters && !spent(&*run) {
        if stop.load(Ordering::Relaxed) {
            checkpoint(&*run, &dir, timing, on_event)?;
            return Ok(None);
        }
        let (loss, psnr, rays_per_s) = match timed_step(run, data, timing, t.batch_rays) {
            Ok(v) => v,
            Err(Error::NonFinite(what)) => {
                return Err(diverged_error(&dir, run.step() + 1, &what, saved));
            }
            Err(e) => return Err(e),
        };
        let step = run.step();
        on_event(&Event::Step {
            step,
            loss,
            psnr,
            rays_per_s,
        });
        let out_of_time = spent(&*run);
        let last = step == t.iters || out_of_time;
        let validate_now = (t.val_every > 0 && step.is_multiple_of(t.val_every)) || last;
        let scores = if validate_now {
            let s = timed_validation(&*run, data, t.val_frames, timing)?;
            if s.non_finite > 0 {
                let what = format!(
                    "{} of {} validation renders hold NaN or infinite values",
                    s.non_finite, s.frames
                );
                return Err(diverged_error(&dir, step, &what, saved));
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
            checkpoint(&*run, &dir, timing, on_event)?;
            saved = Some(step);
        }
        if out_of_time {
            break;
        }
    }
    // A new run whose budget was spent before its first step (on its teacher's targets,
    // say) is still written, at step 0, so that it can be opened, resumed and scored.
    if saved.is_none() && !stop.load(Ordering::Relaxed) {
        checkpoint(&*run, &dir, timing, on_event)?;
    }
    Ok(last_val)
}

/// One training step of `run`, its seconds and its side work's added to `timing`.
/// Returns the loss, the PSNR and the step's own rate in rays per second (without the
/// side work).
fn timed_step(
    run: &mut dyn TrainingRun,
    data: &TrainData,
    timing: &mut Timing,
    batch_rays: usize,
) -> Result<(f64, f64, f64)> {
    let started = Instant::now();
    let (loss, psnr) = run.train_step(data)?;
    let step_s = started.elapsed().as_secs_f64();
    let mut side_s = 0.0;
    for (what, seconds, count) in run.take_side_times() {
        timing.add(what, seconds, count);
        side_s += seconds;
    }
    timing.add(STEPS_PART, step_s - side_s, 1);
    // The step's own rate, without the side work.
    let rays_per_s = batch_rays as f64 / (step_s - side_s).max(1e-9);
    Ok((loss, psnr, rays_per_s))
}

/// The validation scores of `run` on `n` frames, their seconds added to `timing`.
fn timed_validation(
    run: &dyn TrainingRun,
    data: &TrainData,
    n: usize,
    timing: &mut Timing,
) -> Result<Scores> {
    let started = Instant::now();
    let s = run.validation_scores(data, n)?;
    timing.add(VALIDATION_PART, started.elapsed().as_secs_f64(), 1);
    Ok(s)
}

/// The error of a run that diverged at `step` (`what` went NaN or infinite), saying which
/// checkpoint in `dir` is kept.
fn diverged_error(dir: &Path, step: usize, what: &str, saved: Option<usize>) -> Error {
    let kept = match saved {
        Some(s) => format!("the checkpoint of step {s} in {} is kept", dir.display()),
        None => "no checkpoint was written".to_string(),
    };
    Error::NonFinite(format!(
        "training diverged at step {step}: {what}; {kept}; lower the learning rate (`lr`) \
         and train again"
    ))
}

/// Writes `run`'s checkpoint, adds its seconds to `timing` and reports it.
fn checkpoint(
    run: &dyn TrainingRun,
    dir: &Path,
    timing: &mut Timing,
    on_event: &mut dyn FnMut(&Event),
) -> Result<()> {
    let started = Instant::now();
    run.save()?;
    timing.add(CHECKPOINT_PART, started.elapsed().as_secs_f64(), 1);
    on_event(&Event::Checkpoint {
        step: run.step(),
        dir: dir.to_path_buf(),
    });
    Ok(())
}
