//! The frontier's timings beside the scoring pass: every way of rendering back to back, in
//! turns, and AD-NeRF's own setting with seeded weights, in turns with the points it is set
//! against.

use std::time::Instant;

use nldf_core::dataset::{Frame, Split};
use nldf_core::stats::median;
use nldf_train::job::{JobEvent, OnEvent};
use nldf_train::reports::eval::FrameModel;
use nldf_train::trainers::config::{TeacherConfig, TeacherRunConfig};
use nldf_train::trainers::data::TrainData;
use nldf_train::trainers::teacher_trainer::TeacherRun;

use super::front::paired_ratio;
use super::points::Timed;
use super::report::{AdNerfPair, AdNerfSetting};
use crate::error::{Result, temp_dir};

/// Rounds of [`time_back_to_back`].
const BACK_TO_BACK_ROUNDS: usize = 3;

/// Each model's median time per whole frame rendered back to back, interleaved: in each of
/// [`BACK_TO_BACK_ROUNDS`] rounds every model renders one untimed frame, then its share of
/// `frames` back to back. Each frame follows the model's own previous one (warm caches, as
/// a video renders them), and each model's times span the whole timing period, so a drift
/// of the machine's speed over minutes touches every model alike.
pub(crate) fn time_back_to_back(
    models: &[&dyn FrameModel],
    data: &TrainData,
    frames: &[Frame],
) -> Result<Vec<f64>> {
    let rounds = BACK_TO_BACK_ROUNDS.min(frames.len()).max(1);
    let mut times = vec![Vec::with_capacity(frames.len()); models.len()];
    for r in 0..rounds {
        let chunk = &frames[r * frames.len() / rounds..(r + 1) * frames.len() / rounds];
        let Some(first) = chunk.first() else {
            continue;
        };
        for (model, times) in models.iter().zip(times.iter_mut()) {
            model.render_frame(data, first)?;
            for f in chunk {
                let started = Instant::now();
                model.render_frame(data, f)?;
                times.push(started.elapsed().as_secs_f64());
            }
        }
    }
    Ok(times.iter().map(|t| median(t)).collect())
}

/// AD-NeRF's setting timed as the paper compares against it: 8 x 256 with 64 coarse + 128
/// fine samples, every pixel of the frame sampled over `[near, far]` and every sample
/// evaluated. The weights are seeded (training it takes hours on 2 cores), so this is its
/// time per frame, not its quality. It renders `n` `val` frames after an untimed one, and
/// after each of its frames every model of `against` renders the same frame, so that each
/// frame is a pair for each model's speed-up.
pub(crate) fn time_adnerf_setting(
    data: &TrainData,
    n: usize,
    against: &[&dyn FrameModel],
    on_event: OnEvent,
) -> Result<AdNerfSetting> {
    let cfg = TeacherRunConfig {
        model: TeacherConfig::ad_nerf(),
        ..TeacherRunConfig::default()
    };
    let scratch = temp_dir()?;
    let run = TeacherRun::create(scratch.path(), cfg, data)?;
    let timed = Timed::new(&run.model, false, false);
    let frames = data.dataset.frames(Split::Val);
    on_event(&JobEvent::Note(format!(
        "timing AD-NeRF's setting on {n} frames after an untimed one (seeded weights), taking \
         turns with {} points",
        against.len()
    )));
    let seconds = |model: &dyn FrameModel, f: &Frame| -> Result<f64> {
        let started = Instant::now();
        model.render_frame(data, f)?;
        Ok(started.elapsed().as_secs_f64())
    };
    let mut own = Vec::with_capacity(n);
    let mut theirs = vec![Vec::with_capacity(n); against.len()];
    for (k, f) in frames.iter().cycle().take(n + 1).enumerate() {
        let s = seconds(&timed, f)?;
        let others = against
            .iter()
            .map(|m| seconds(*m, f))
            .collect::<Result<Vec<_>>>()?;
        if k > 0 {
            own.push(s);
            for (t, s) in theirs.iter_mut().zip(others) {
                t.push(s);
            }
        }
    }
    let pixels = (data.dataset.intrinsics.width * data.dataset.intrinsics.height) as f64;
    Ok(AdNerfSetting {
        ms_2_threads: 1e3 * median(&own),
        gmac_per_frame: pixels * run.model.macs_per_ray() / 1e9,
        frames: n,
        against: against
            .iter()
            .zip(&theirs)
            .map(|(m, t)| AdNerfPair {
                point: m.describe(),
                ms: 1e3 * median(t),
                speed_up: paired_ratio(&own, t),
            })
            .collect(),
    })
}
