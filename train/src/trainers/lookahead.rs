//! A short-lookahead student: a trained student whose audio encoder is distilled again so
//! that it reads at most a given span of future audio, so that a stream renders each
//! frame sooner. The rest of the student is kept as it is.
//!
//! AD-NeRF's window of 16 feature frames is centred on the video frame: it reads 152.5 ms
//! past the frame's instant at nldf's defaults. The short-lookahead encoder `E'` reads the
//! same window with its rows past `window / 2 + ahead` zeroed ([`AudioConfig::rows_read`]),
//! and learns to give the code the full encoder `E` gives the full window, on the training
//! frames' windows:
//!
//! ```text
//! min  mean_f || E'(mask . x_f + g_f) - E(x_f + g_f) ||^2
//! ```
//!
//! where `g_f` is a random loudness offset per window (the log-mel features shift by
//! `dB / 50` for a gain of `dB`), which the two encoders see alike, so that the codes stay
//! right for a voice recorded louder or softer. `E'` starts as `E`; the student's
//! light-field network reads `E'`'s codes as it read `E`'s. The teacher is not touched.
//!
//! [`AudioConfig::rows_read`]: nldf_core::student_config::AudioConfig::rows_read

use std::path::Path;

use candle_core::{Device, Tensor, Var};
use nldf_core::audio::{FeatureConfig, FeatureSource};
use nldf_core::dataset::Split;
use nldf_core::render_spec::{BACKGROUND_FILE, RENDER_SPEC_FILE};
use nldf_core::run_files::{CONFIG_FILE, LOG_FILE};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::networks::nn::sorted_vars;
use crate::trainers::adam::{Adam, AdamParams};
use crate::trainers::checkpoint::{CheckpointParts, Clock, save_checkpoint, save_json};
use crate::trainers::data::TrainData;
use crate::trainers::log::CsvLog;
use crate::trainers::student_trainer::StudentModel;

/// The report a short-lookahead student's folder holds.
pub const LOOKAHEAD_REPORT_FILE: &str = "lookahead.json";

/// How the short-lookahead encoder is distilled. Defaults: 100 ms, 1500 full-batch steps,
/// the learning rate 1e-3 decaying exponentially to 1e-5, gains within ±6 dB, seed 0.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LookaheadConfig {
    /// The most future audio the encoder may read, in milliseconds past a frame's instant.
    pub lookahead_ms: f64,
    /// Optimizer steps, each over every training frame's window.
    pub steps: usize,
    pub lr: f64,
    pub lr_final: f64,
    /// Each step gives each window a random loudness within ± this many decibels.
    pub gain_db: f64,
    pub seed: u64,
}

impl Default for LookaheadConfig {
    fn default() -> Self {
        LookaheadConfig {
            lookahead_ms: 100.0,
            steps: 1500,
            lr: 1e-3,
            lr_final: 1e-5,
            gain_db: 6.0,
            seed: 0,
        }
    }
}

/// How far the short-lookahead codes lie from the full encoder's on one set of windows:
/// the mean squared difference as a share of the variance of the full encoder's codes of
/// the training frames (0: the same codes).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct CodeError {
    /// Which frames: `train`, `val`, `voice`.
    pub frames: String,
    pub n: usize,
    /// The full encoder on the masked windows, before any training.
    pub before: f64,
    /// The distilled encoder.
    pub after: f64,
}

/// What [`train_lookahead`] did.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LookaheadReport {
    pub config: LookaheadConfig,
    /// The student it was distilled from (a folder of the run).
    pub source: String,
    /// Feature frames read past the window's centre, and the lookahead they make.
    pub ahead: usize,
    pub lookahead_ms: f64,
    /// The full encoder's lookahead.
    pub full_lookahead_ms: f64,
    pub train_s: f64,
    pub final_loss: f64,
    /// Per set of frames: the training frames', then each held-out set's.
    pub code_error: Vec<CodeError>,
}

/// Held-out windows to report the code error on: a name and `[n, att_frames, window, F]`.
pub type HeldOutWindows = (String, Tensor);

/// Distils a short-lookahead student from the student in `source` (a trained student
/// folder) into `dir`, on the training frames of `data` (the dataset the student was
/// trained on, with its features), and reports the code error on `held_out` too. Writes
/// `config.json` (the student's, with `model.audio.ahead`), the render spec and
/// background, the checkpoint, `log.csv` and [`LOOKAHEAD_REPORT_FILE`].
pub fn train_lookahead(
    source: &Path,
    dir: &Path,
    cfg: &LookaheadConfig,
    data: &TrainData,
    held_out: &[HeldOutWindows],
    on_step: &mut dyn FnMut(usize, f64),
) -> Result<LookaheadReport> {
    let full = StudentModel::open(source)
        .map_err(|e| e.context(format!("loading the student from {}", source.display())))?;
    let features = lookahead_features(source, &full, cfg)?;
    let window = full.cfg.model.audio.window;
    let ahead = features
        .ahead_within(cfg.lookahead_ms / 1e3)
        .ok_or_else(|| {
            Error::Config(format!(
                "a lookahead of {} ms is shorter than one feature frame past the centre ({:.1} \
             ms)",
                cfg.lookahead_ms,
                1e3 * features.lookahead_s(1)
            ))
        })?;
    let mut run_cfg = full.cfg.clone();
    run_cfg.model.audio.ahead = Some(ahead);
    let short = StudentModel::build(dir, run_cfg)?;
    copy_weights(&full, &short)?;
    let train_ids: Vec<usize> = data
        .dataset
        .frames(Split::Train)
        .iter()
        .map(|f| f.aud_id)
        .collect();
    let windows = data.neighbourhoods(&train_ids, full.cfg.model.audio.att_frames)?;
    let mut sets = vec![("train".to_string(), windows.clone())];
    sets.extend(held_out.iter().cloned());
    let before = code_errors(&full, &short, &sets)?;

    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    for file in [RENDER_SPEC_FILE, BACKGROUND_FILE] {
        let (from, to) = (source.join(file), dir.join(file));
        std::fs::copy(&from, &to).map_err(|e| Error::io(&from, e))?;
    }
    save_json(&dir.join(CONFIG_FILE), &short.cfg)?;
    let (train_s, final_loss) = distil(&full, &short, dir, cfg, &windows, on_step)?;
    let after = code_errors(&full, &short, &sets)?;
    let report = LookaheadReport {
        config: cfg.clone(),
        source: source
            .file_name()
            .map_or_else(String::new, |n| n.to_string_lossy().into_owned()),
        ahead,
        lookahead_ms: 1e3 * features.lookahead_s(ahead),
        full_lookahead_ms: 1e3 * features.lookahead_s(window / 2),
        train_s,
        final_loss,
        code_error: before
            .into_iter()
            .zip(after)
            .map(|((frames, n, before), (_, _, after))| CodeError {
                frames,
                n,
                before,
                after,
            })
            .collect(),
    };
    save_json(&dir.join(LOOKAHEAD_REPORT_FILE), &report)?;
    Ok(report)
}

/// The front end of the student `full` (in `source`), refused when a short lookahead
/// cannot apply: another front end's features, attention, or settings out of range.
fn lookahead_features<'a>(
    source: &Path,
    full: &'a StudentModel,
    cfg: &LookaheadConfig,
) -> Result<&'a FeatureConfig> {
    let audio = &full.cfg.model.audio;
    let FeatureSource::Nldf(features) = &audio.features else {
        return Err(Error::Config(format!(
            "{}: its audio features come from another front end ({}); a short lookahead \
             needs nldf's own, which a stream can make",
            source.display(),
            audio.features.describe()
        )));
    };
    if full.cfg.model.attention {
        return Err(Error::Config(format!(
            "{}: the student fuses its neighbours' windows with attention, which read up to \
             {} frames ahead; a short lookahead needs a student without attention",
            source.display(),
            audio.att_frames / 2
        )));
    }
    if !(cfg.lookahead_ms.is_finite() && cfg.steps > 0 && cfg.lr > 0.0 && cfg.lr_final > 0.0) {
        return Err(Error::Config(format!(
            "the lookahead needs a finite lookahead, steps and positive learning rates, got \
             {} ms, {} steps, lr {} to {}",
            cfg.lookahead_ms, cfg.steps, cfg.lr, cfg.lr_final
        )));
    }
    Ok(features)
}

/// The distillation itself: `cfg.steps` full-batch Adam steps of `short`'s audio encoder
/// towards `full`'s codes on `windows` (`[n, att_frames, window, F]`), each at random
/// loudness; checkpoints `short` into `dir` and returns the seconds taken and the last loss.
fn distil(
    full: &StudentModel,
    short: &StudentModel,
    dir: &Path,
    cfg: &LookaheadConfig,
    windows: &Tensor,
    on_step: &mut dyn FnMut(usize, f64),
) -> Result<(f64, f64)> {
    let encoder: Vec<(String, Var, f64)> = sorted_vars(&short.varmap)?
        .into_iter()
        .filter(|(name, _)| name.starts_with("audio."))
        .map(|(n, v)| (n, v, 1.0))
        .collect();
    let mut adam = Adam::new(
        encoder,
        AdamParams {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
        },
    );
    let mut log = CsvLog::open(&dir.join(LOG_FILE), 0)?;
    let clock = Clock::resumed(0.0);
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    let n = windows.dim(0)?;
    let mut loss = f64::NAN;
    for step in 1..=cfg.steps {
        let gains: Vec<f32> = (0..n)
            .map(|_| (rng.random_range(-cfg.gain_db..=cfg.gain_db) / 50.0) as f32)
            .collect();
        let gains = Tensor::from_vec(gains, (n, 1, 1, 1), &Device::Cpu)?;
        let x = windows.broadcast_add(&gains)?;
        let target = full.student.audio_codes(&x)?.detach();
        let l = (short.student.audio_codes(&x)? - target)?
            .sqr()?
            .mean_all()?;
        let grads = l.backward()?;
        let frac = (step - 1) as f64 / (cfg.steps.max(2) - 1) as f64;
        let lr = cfg.lr * (cfg.lr_final / cfg.lr).powf(frac);
        adam.step(&grads, lr)?;
        loss = l.to_scalar::<f32>()? as f64;
        if !loss.is_finite() {
            return Err(Error::NonFinite(format!(
                "the short-lookahead encoder's loss became {loss} at step {step}"
            )));
        }
        if step % 50 == 0 || step == cfg.steps {
            let psnr = -10.0 * loss.max(1e-30).log10();
            log.row(step, clock.elapsed(), loss, psnr, lr, 0.0, None)?;
        }
        on_step(step, loss);
    }
    let train_s = clock.elapsed();
    save_checkpoint(&CheckpointParts {
        dir,
        kind: "student",
        step: full.step,
        elapsed: full.trained_s + train_s,
        varmap: &short.varmap,
        adam: &adam,
        title: "short-lookahead audio encoder (code error)",
    })?;
    Ok((train_s, loss))
}

/// Sets every weight of `to` to `from`'s (the two share the network's shape).
fn copy_weights(from: &StudentModel, to: &StudentModel) -> Result<()> {
    let source = sorted_vars(&from.varmap)?;
    for (name, var) in sorted_vars(&to.varmap)? {
        let (_, v) = source
            .iter()
            .find(|(n, _)| *n == name)
            .ok_or_else(|| Error::Config(format!("the student holds no weight `{name}`")))?;
        var.set(v.as_tensor())?;
    }
    Ok(())
}

/// Per set: its name, its size, and the short encoder's code error against the full one
/// (the mean squared difference over the variance of the full codes of the first set, the
/// training frames', so that every set is measured on one scale).
fn code_errors(
    full: &StudentModel,
    short: &StudentModel,
    sets: &[HeldOutWindows],
) -> Result<Vec<(String, usize, f64)>> {
    let mut scale = None;
    sets.iter()
        .map(|(name, x)| {
            let target = full.student.audio_codes(x)?;
            let got = short.student.audio_codes(x)?;
            let n = target.dim(0)?;
            let err = (got - &target)?.sqr()?.mean_all()?.to_scalar::<f32>()? as f64;
            let var = match scale {
                Some(v) => v,
                None => {
                    let mean = target.mean_keepdim(0)?;
                    let v = target
                        .broadcast_sub(&mean)?
                        .sqr()?
                        .mean_all()?
                        .to_scalar::<f32>()? as f64;
                    *scale.insert(v.max(1e-12))
                }
            };
            Ok((name.clone(), n, err / var))
        })
        .collect()
}
