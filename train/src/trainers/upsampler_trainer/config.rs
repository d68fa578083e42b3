//! How an upsampler run is configured: its network and training settings, as saved in
//! its `config.json`.

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::networks::upsampler::UpsamplerConfig;

/// How the upsampler is trained.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct UpsamplerTrainConfig {
    pub seed: u64,
    /// Optimizer steps.
    pub iters: usize,
    /// Crops per step.
    pub batch: usize,
    /// Coarse rays on a side of the part of a crop the loss counts.
    pub crop: usize,
    /// Coarse rays of context around it on each side.
    pub halo: usize,
    /// Adam's learning rate at the start; it decays exponentially to `lr_final`.
    pub lr: f64,
    pub lr_final: f64,
    /// Pseudo views the teacher renders crops of (their poses drawn as the student's own
    /// pseudo views are, `pose_range` and `pseudo_zoom` of its recipe).
    pub pseudo_views: usize,
    /// Crops the teacher renders per pseudo view.
    pub pseudo_crops: usize,
    /// Share of each step's crops taken from pseudo views.
    pub pseudo_fraction: f64,
    /// Share of the recorded crops centred near a pixel of the frame's mouth region (its
    /// parsing or region labels), whose detail is small and moves with the audio.
    pub mouth_fraction: f64,
    /// Steps between rows of `log.csv`.
    pub log_every: usize,
    /// Whether to find the mouth's box from the teacher ([`super::mouth_patch_box`]) and
    /// save it as the model's `mouth_patch`, so that the frame graph and candle's renderer
    /// draw the mouth with the student's own rays at full resolution over the upsampled
    /// frame. Off by default: at 256 x 256 on the standard head the patch added 71 % to
    /// the student's rays at the default pose (3510 against 2055) and cost 24 % of native
    /// onnxruntime's frame rate in int8 (docs/sharp.md, "The mouth patch").
    pub mouth_patch: bool,
}

impl Default for UpsamplerTrainConfig {
    fn default() -> Self {
        UpsamplerTrainConfig {
            seed: 0,
            iters: 2000,
            batch: 8,
            crop: 12,
            halo: 2,
            lr: 2e-3,
            lr_final: 1e-4,
            pseudo_views: 150,
            pseudo_crops: 2,
            pseudo_fraction: 0.5,
            mouth_fraction: 0.3,
            log_every: 25,
            mouth_patch: false,
        }
    }
}

/// Everything an upsampler run needs, as saved in its `config.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(default, deny_unknown_fields)]
pub struct UpsamplerRunConfig {
    pub model: UpsamplerConfig,
    /// The student's folder in the run, whose hidden layer the CNN reads.
    pub student: String,
    pub train: UpsamplerTrainConfig,
}

impl UpsamplerRunConfig {
    /// Checks every setting.
    pub fn check(&self) -> Result<()> {
        self.model.check("model")?;
        let t = &self.train;
        let range = |key: &str, ok: bool| {
            if ok {
                Ok(())
            } else {
                Err(Error::Config(format!("`train.{key}` is out of range")))
            }
        };
        range("iters", t.iters <= 1 << 24)?;
        range("batch", (1..=256).contains(&t.batch))?;
        range("crop", (1..=256).contains(&t.crop))?;
        range("halo", t.halo <= 16)?;
        range("lr", t.lr > 0.0 && t.lr <= 1.0)?;
        range("lr_final", t.lr_final > 0.0 && t.lr_final <= t.lr)?;
        range("pseudo_views", t.pseudo_views <= 1 << 16)?;
        range("pseudo_crops", (1..=64).contains(&t.pseudo_crops))?;
        range("pseudo_fraction", (0.0..=1.0).contains(&t.pseudo_fraction))?;
        range("mouth_fraction", (0.0..=1.0).contains(&t.mouth_fraction))?;
        range("log_every", t.log_every >= 1)?;
        if self.student.is_empty() {
            return Err(Error::Config(
                "`student` must name the student's folder".into(),
            ));
        }
        Ok(())
    }
}
