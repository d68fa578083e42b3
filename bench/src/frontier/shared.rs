//! What the frontier's passes share: the job's settings, the threads and precisions it
//! measures, and scoring one split.

use std::path::{Path, PathBuf};

use nldf_core::dataset::Split;
use nldf_export::WeightType;
use nldf_train::job::{JobEvent, OnEvent};
use nldf_train::reports::eval::{Evaluation, FrameModel, eval_models};
use nldf_train::trainers::data::TrainData;

use crate::error::Result;
use crate::load::LoadGate;

/// Threads of the main timing.
pub const THREADS: usize = 2;

/// Precisions every student is exported in.
pub(super) const PRECISIONS: [WeightType; 3] = [WeightType::F32, WeightType::F16, WeightType::Int8];

pub(super) fn precision_name(w: WeightType) -> &'static str {
    match w {
        WeightType::F32 => "fp32",
        WeightType::F16 => "fp16",
        WeightType::Int8 => "int8",
    }
}

/// What the frontier measures, and where its files go.
#[derive(Debug, Clone)]
pub struct FrontierJob {
    /// Run folder: its teacher and every student in it.
    pub run: PathBuf,
    /// The dataset the run was trained on (its `val` split, and `novel` and `voice` where
    /// `nldf synth` wrote them).
    pub data: PathBuf,
    /// Output folder (the exports, each split's renders, the report).
    pub out: PathBuf,
    /// At most this many frames per split, spread evenly.
    pub frames: Option<usize>,
    /// Frames timed with 1 thread per point.
    pub one_thread_frames: usize,
    /// Training frames that calibrate the int8 exports.
    pub calibration_frames: usize,
    /// Rays per network call.
    pub batch: usize,
    /// Frames timed for AD-NeRF's setting; 0 leaves it out.
    pub adnerf_frames: usize,
    /// The same scene at a higher resolution, scored and timed apart.
    pub hires_data: Option<PathBuf>,
    /// Frames each point also renders back to back, for a second 2-thread median.
    pub timed_frames: usize,
    /// Learned upsamplers of the run (their folders) whose upsampled ray graphs join the
    /// frontier, in fp16 and with int8 products.
    pub upsamplers: Vec<String>,
    /// The student's products kept in f32 in those int8 graphs (`--int8-f32`).
    pub int8_f32: Vec<String>,
    /// The load limit at the start.
    pub load: LoadGate,
}

/// [`eval_counted`] on at most `frames` frames of `split`, after a note of how many frames
/// and ways of rendering.
pub(super) fn eval_split(
    models: &[&dyn FrameModel],
    data: &TrainData,
    split: Split,
    frames: Option<usize>,
    out: &Path,
    on_event: OnEvent,
) -> Result<Evaluation> {
    let n = frames
        .unwrap_or(usize::MAX)
        .min(data.dataset.frames(split).len());
    on_event(&JobEvent::Note(format!(
        "{}: {n} frames x {} ways of rendering",
        split.name(),
        models.len()
    )));
    eval_counted(models, data, split, frames, out, n, on_event)
}

/// [`eval_models`] on `n` frames of `split`, each scored frame told as progress of
/// `split`'s name, and its renders checked finite.
pub(super) fn eval_counted(
    models: &[&dyn FrameModel],
    data: &TrainData,
    split: Split,
    frames: Option<usize>,
    out: &Path,
    n: usize,
    on_event: OnEvent,
) -> Result<Evaluation> {
    let what = split.name().to_string();
    let progress = |done: usize| JobEvent::Progress {
        what: what.clone(),
        done,
        total: n,
    };
    on_event(&progress(0));
    let mut done = 0;
    let evaluation = eval_models(models, data, split, frames, out, &mut || {
        done += 1;
        on_event(&progress(done));
    })?;
    if done < n {
        on_event(&progress(n));
    }
    evaluation.check_finite()?;
    Ok(evaluation)
}
