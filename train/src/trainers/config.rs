//! Serde configurations of the teacher's and the student's trainers (and the teacher's shape,
//! [`TeacherConfig`], from [`crate::networks::teacher_config`]), with documented defaults
//! and presets that say which anchor they follow. The resolved configuration is saved beside every
//! checkpoint as `config.json` and read back by later stages.
//!
//! Reading is strict ([`read_config`], in [`crate::trainers::config_file`]): an unknown key or a value of the wrong type is an
//! error naming the key, and each run configuration's `check` names the key whose value is
//! out of range, before any work starts.

use serde::{Deserialize, Serialize};

use nldf_core::checks::{MAX_WIDTH, at_least, in_range, in_range_open, positive};
pub use nldf_core::student_config::AudioConfig;

pub use crate::networks::teacher_config::TeacherConfig;

use crate::error::{Error, Result};
pub use crate::trainers::config_file::{
    RunConfig, check_config, parse_checked, parse_config, read_checked, read_config,
};

/// The checks of the fields the teacher's and the student's `train` sections share (same
/// names, same meaning): batches, fractions, learning rate, Adam, logging and time budget.
macro_rules! check_shared_train {
    ($t:expr) => {
        let t = $t;
        at_least("train.iters", t.iters, 1)?;
        in_range("train.batch_rays", t.batch_rays, 1, MAX_BATCH)?;
        in_range("train.frames_per_batch", t.frames_per_batch, 1, 4096)?;
        in_range("train.face_fraction", t.face_fraction, 0.0, 1.0)?;
        in_range("train.mouth_fraction", t.mouth_fraction, 0.0, 1.0)?;
        positive("train.lr", t.lr, 1.0)?;
        at_least("train.lr_decay_steps", t.lr_decay_steps, 1)?;
        in_range_open("train.beta1", t.beta1, 0.0, 1.0)?;
        in_range_open("train.beta2", t.beta2, 0.0, 1.0)?;
        positive("train.eps", t.eps, 1.0)?;
        at_least("train.log_every", t.log_every, 1)?;
        in_range("train.val_frames", t.val_frames, 1, 4096)?;
        in_range("train.time_budget_s", t.time_budget_s, 0.0, 1e9)?;
        in_range("train.time_cap_s", t.time_cap_s, 0.0, 1e9)?;
    };
}

/// Largest network width, sample count and batch the checks accept: far beyond any preset,
/// small enough that a typo cannot ask for terabytes.
const MAX_DEPTH: usize = 256;
const MAX_SAMPLES: usize = 1024;
const MAX_BATCH: usize = 1 << 20;
const MAX_FREQS: usize = 16;

/// How the teacher is trained.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TeacherTrainConfig {
    /// Seed of the ray batches and the initial weights.
    pub seed: u64,
    /// Training steps.
    pub iters: usize,
    /// Rays per step (AD-NeRF: 2048 from one frame).
    pub batch_rays: usize,
    /// Frames each step draws its rays from (AD-NeRF: 1).
    pub frames_per_batch: usize,
    /// Fraction of rays inside `face_rect` (AD-NeRF: 0.95).
    pub face_fraction: f32,
    /// Fraction of rays drawn from the mouth region when the dataset has parsing masks
    /// (ours: the mouth is a few percent of the face but carries the audio's effect;
    /// AD-NeRF: 0).
    pub mouth_fraction: f32,
    /// Adam learning rate at step 0 (AD-NeRF: 5e-4; twice that suits the short runs here).
    pub lr: f64,
    /// Steps over which the learning rate decays by 10x (AD-NeRF: 500k; here the length of
    /// the default run).
    pub lr_decay_steps: usize,
    /// Steps the learning rate is held at `lr` before it starts to decay (0: decays from
    /// the first step).
    pub lr_hold_steps: usize,
    /// Step from which AudioAttNet fuses neighbouring frames (AD-NeRF: 200k of ~400k).
    pub att_start: usize,
    /// AudioAttNet's learning rate as a multiple of `lr` (AD-NeRF: 5).
    pub att_lr_scale: f64,
    /// Adam's first-moment decay.
    pub beta1: f64,
    /// Adam's second-moment decay.
    pub beta2: f64,
    /// Adam's epsilon.
    pub eps: f64,
    /// Steps between lines of `log.csv`.
    pub log_every: usize,
    /// Steps between validations (0: only at the end).
    pub val_every: usize,
    /// Validation frames rendered each time (spread evenly over the split).
    pub val_frames: usize,
    /// Steps between checkpoints (also written at the end and on Ctrl-C).
    pub checkpoint_every: usize,
    /// Training seconds after which the run ends early, validated and checkpointed
    /// (0: no limit; counts across resumes). The learning rate follows it too (held, then
    /// decayed over its last 40 %), so a budgeted run's result depends on the machine.
    pub time_budget_s: f64,
    /// A wall-clock cap in seconds that only stops the run (0: none): the learning rate
    /// follows the steps alone, so a recipe pinned in steps trains the same on any
    /// machine, and the cap says when a slow one cut it short.
    pub time_cap_s: f64,
}

impl Default for TeacherTrainConfig {
    fn default() -> Self {
        TeacherTrainConfig {
            seed: 0,
            iters: 6000,
            batch_rays: 1024,
            frames_per_batch: 4,
            face_fraction: 0.95,
            mouth_fraction: 0.1,
            lr: 1e-3,
            lr_decay_steps: 6000,
            lr_hold_steps: 0,
            att_start: 3000,
            att_lr_scale: 5.0,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
            log_every: 20,
            val_every: 500,
            val_frames: 4,
            checkpoint_every: 500,
            time_budget_s: 0.0,
            time_cap_s: 0.0,
        }
    }
}

/// Everything a teacher run needs, as saved in `config.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(default, deny_unknown_fields)]
pub struct TeacherRunConfig {
    pub model: TeacherConfig,
    pub train: TeacherTrainConfig,
}

impl RunConfig for TeacherRunConfig {
    fn check(&self) -> Result<()> {
        let m = &self.model;
        m.audio.check("model.audio")?;
        in_range("model.depth", m.depth, 1, MAX_DEPTH)?;
        in_range("model.width", m.width, 1, MAX_WIDTH)?;
        in_range("model.color_width", m.color_width, 1, MAX_WIDTH)?;
        in_range("model.pos_freqs", m.pos_freqs, 0, MAX_FREQS)?;
        in_range("model.dir_freqs", m.dir_freqs, 0, MAX_FREQS)?;
        in_range("model.n_samples", m.n_samples, 2, MAX_SAMPLES)?;
        in_range("model.n_importance", m.n_importance, 0, MAX_SAMPLES)?;
        if let Some(&s) = m.skips.iter().find(|&&s| s + 1 >= m.depth) {
            return Err(Error::Config(format!(
                "`model.skips` must name layers before the last of `model.depth` {}, got {s}",
                m.depth
            )));
        }
        in_range_open(
            "model.min_transmittance",
            m.min_transmittance as f64,
            0.0,
            1.0,
        )?;
        if let Some(g) = &m.grid {
            g.check("model.grid")?;
        }
        if let Some(o) = &m.occupancy {
            if m.grid.is_none() {
                return Err(Error::Config(
                    "`model.occupancy` needs the grid teacher: set `model.grid` too".into(),
                ));
            }
            o.check("model.occupancy")?;
        }
        let t = &self.train;
        check_shared_train!(t);
        positive("train.att_lr_scale", t.att_lr_scale, 1e3)?;
        Ok(())
    }
}

/// How the student is trained (paper sections 3.4-3.5; R2L's public settings where the
/// paper is silent).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StudentTrainConfig {
    /// Seed of the ray batches, the beam jitter and the initial weights.
    pub seed: u64,
    /// Training steps.
    pub iters: usize,
    /// Rays per step (paper: 4096).
    pub batch_rays: usize,
    /// Frames each step draws its rays from.
    pub frames_per_batch: usize,
    /// Fraction of rays inside `face_rect` (paper: 0.9); the rest come from the other
    /// pixels whose rays hit the head's bounds.
    pub face_fraction: f32,
    /// Fraction of rays drawn from the mouth region when the dataset has parsing masks
    /// (counted inside the face fraction; the teacher's setting).
    pub mouth_fraction: f32,
    /// Weight of a mouth ray's loss against another ray's (1: none): the mouth is a few
    /// percent of the head but carries the audio's effect.
    pub mouth_weight: f32,
    /// Find a pseudo view's mouth by projecting its source frame's mouth pixels through
    /// the teacher's depth (off: the source frame's mouth pixels as they are, which miss
    /// the mouth once the head turns).
    pub project_mouth: bool,
    /// The teacher's accumulated weight below which a target counts as empty (opacity 0,
    /// no colour), so that the student is not taught the teacher's faint haze far from the
    /// head; 0 (the default) keeps every target as the teacher renders it.
    pub opacity_floor: f32,
    /// Weight averaging: from the step the learning rate starts to decay, keep an
    /// exponential moving average of the weights with this decay per step (0, the default:
    /// none; 0.998 averages over about the last 500 steps), and end the run on it: the
    /// last validation, the last checkpoint and every export use the average. A run resumed
    /// mid-way starts its average again at the resumed step.
    pub ema_decay: f64,
    /// The audio encoder's learning rate as a factor of the rest's: a distilled student
    /// starts from its teacher's encoder, and 0 keeps that encoder as it is (1, the
    /// default: trained with the rest).
    pub audio_lr_scale: f64,
    /// Adam learning rate at step 0 (R2L: 5e-4).
    pub lr: f64,
    /// Steps over which the learning rate decays by 10x.
    pub lr_decay_steps: usize,
    /// Steps the learning rate is held at `lr` before it starts to decay (0: decays from
    /// the first step). A hold then a short decay lets a run at a high rate settle at the
    /// end, where the validation scores of a constant rate swing by about 1 dB.
    pub lr_hold_steps: usize,
    /// Adam's moment decays and epsilon.
    pub beta1: f64,
    pub beta2: f64,
    pub eps: f64,
    /// Distil from the teacher's segment colours (Eq. 6); off: pixels only (Eq. 8).
    pub distill: bool,
    /// Weight of the segment loss, lambda of Eq. 9 (paper: 0.2).
    pub lambda: f64,
    /// Keep an active beam pool (paper section 3.5).
    pub pool: bool,
    /// Fraction of each batch's highest-loss beams that enter the pool, and the size of the
    /// pool batch as a fraction of the batch (R2L: 0.2).
    pub hard_ratio: f64,
    /// Pool capacity in batches (R2L: 20).
    pub pool_batches: usize,
    /// Jitter the beam points along each ray while training (R2L).
    pub jitter: bool,
    /// Views beyond the training frames whose teacher colours the student also learns
    /// from (R2L's pseudo data; distillation only): each turns a training frame's camera
    /// about the head's centre to a pose drawn from the widened recorded range
    /// (`pose_range`), keeping that frame's recorded audio, so the student sees the
    /// teacher's answer at poses the recording lacks. The teacher renders them in chunks
    /// while the student trains (see `pseudo_per_step`). 0: training frames only.
    pub pseudo_frames: usize,
    /// Share of each batch's frames drawn from the pseudo views (of those rendered so far).
    pub pseudo_fraction: f32,
    /// How wide the pseudo views' yaw and pitch range, as a factor of the recorded range
    /// about its middle (1: the recorded poses only; 2: twice as wide).
    pub pose_range: f32,
    /// Largest change of a pseudo view's camera distance, as a fraction of it.
    pub pseudo_zoom: f32,
    /// Hit pixels the teacher renders per pseudo view (its mouth first, the rest drawn at
    /// random; 0: all of them, about 8000 for the synthetic head at 128 x 128). The student
    /// draws a few hundred rays from a view per step, so fewer pixels per view buy more
    /// views for the same teacher time: 2000 views of 1024 rays (a quarter of the teacher
    /// time of 1000 whole views) took a real-time student 2.9 dB higher on `val` and 2.0
    /// dB on `novel` than 1000 whole views, in the same 15 minutes.
    pub pseudo_rays: usize,
    /// Hit pixels of each recorded frame the student learns from and the teacher renders
    /// targets for (its mouth first, the rest drawn at random; 0: all). The teacher's
    /// targets of every pixel of every recorded frame cost minutes, and a short run visits
    /// each pixel only a few times.
    pub recorded_rays: usize,
    /// Pseudo views the teacher renders before each training step until all are done, so
    /// the student starts at once.
    pub pseudo_per_step: usize,
    /// Steps between lines of `log.csv`.
    pub log_every: usize,
    /// Steps between validations (0: only at the end).
    pub val_every: usize,
    /// Validation frames rendered each time.
    pub val_frames: usize,
    /// Steps between checkpoints (also at the end and on Ctrl-C).
    pub checkpoint_every: usize,
    /// Training seconds after which the run ends early (0: no limit). The learning rate
    /// follows it too (see [`decayed_learning_rate`]).
    pub time_budget_s: f64,
    /// A wall-clock cap in seconds that only stops the run (0: none); the learning rate
    /// follows the steps alone.
    pub time_cap_s: f64,
}

impl StudentTrainConfig {
    /// The learning rate at `step` after `elapsed_s` training seconds
    /// ([`decayed_learning_rate`] with the hold).
    pub fn learning_rate(&self, step: usize, elapsed_s: f64) -> f64 {
        decayed_learning_rate(
            self.lr,
            step.saturating_sub(self.lr_hold_steps),
            self.lr_decay_steps,
            elapsed_s,
            self.time_budget_s,
        )
    }
}

/// Share of a time budget the learning rate is held before it decays over the rest.
pub const BUDGET_HOLD: f64 = 0.6;

/// `lr 0.1^p`: the learning rate decays tenfold over `decay_steps` steps, and, when a time
/// budget is set, is also held for the first [`BUDGET_HOLD`] of the budget and then decays
/// tenfold over the rest, whichever is further along:
/// `p = max(step / decay_steps, (elapsed_s / budget_s - h) / (1 - h))`. A run cut by its
/// budget thus ends at a tenth of its rate instead of stopping while the rate is still
/// high; held first, since a rate decayed from the first step ran the measured students'
/// last steps too low (see the README's schedule comparison).
pub fn decayed_learning_rate(
    lr: f64,
    step: usize,
    decay_steps: usize,
    elapsed_s: f64,
    budget_s: f64,
) -> f64 {
    let by_steps = step as f64 / decay_steps.max(1) as f64;
    let by_time = if budget_s > 0.0 && elapsed_s.is_finite() {
        ((elapsed_s / budget_s - BUDGET_HOLD) / (1.0 - BUDGET_HOLD)).clamp(0.0, 1.0)
    } else {
        0.0
    };
    lr * 0.1f64.powf(by_steps.max(by_time))
}

impl Default for StudentTrainConfig {
    fn default() -> Self {
        StudentTrainConfig {
            seed: 0,
            iters: 3000,
            batch_rays: 4096,
            frames_per_batch: 8,
            face_fraction: 0.9,
            mouth_fraction: 0.1,
            mouth_weight: 1.0,
            project_mouth: true,
            opacity_floor: 0.0,
            ema_decay: 0.0,
            audio_lr_scale: 1.0,
            lr: 5e-4,
            lr_decay_steps: 3000,
            lr_hold_steps: 0,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
            distill: true,
            lambda: 0.2,
            pool: true,
            hard_ratio: 0.2,
            pool_batches: 20,
            jitter: true,
            pseudo_frames: 0,
            pseudo_fraction: 0.5,
            pose_range: 2.0,
            pseudo_zoom: 0.15,
            pseudo_rays: 1024,
            recorded_rays: 0,
            pseudo_per_step: 2,
            log_every: 10,
            val_every: 250,
            val_frames: 4,
            checkpoint_every: 250,
            time_budget_s: 0.0,
            time_cap_s: 0.0,
        }
    }
}

/// Everything a student run needs, as saved in its `config.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(default, deny_unknown_fields)]
pub struct StudentRunConfig {
    pub model: nldf_core::student_config::StudentConfig,
    pub train: StudentTrainConfig,
}

impl RunConfig for StudentRunConfig {
    fn check(&self) -> Result<()> {
        self.model.check()?;
        let t = &self.train;
        check_shared_train!(t);
        in_range("train.lambda", t.lambda, 0.0, 1e6)?;
        in_range("train.mouth_weight", t.mouth_weight, 0.0, 1e3)?;
        in_range("train.opacity_floor", t.opacity_floor, 0.0, 1.0)?;
        in_range("train.ema_decay", t.ema_decay, 0.0, 0.999999)?;
        in_range("train.audio_lr_scale", t.audio_lr_scale, 0.0, 100.0)?;
        in_range("train.hard_ratio", t.hard_ratio, 0.0, 1.0)?;
        in_range("train.pool_batches", t.pool_batches, 1, 1024)?;
        in_range("train.pseudo_frames", t.pseudo_frames, 0, 1 << 16)?;
        in_range("train.pseudo_fraction", t.pseudo_fraction, 0.0, 1.0)?;
        in_range("train.pose_range", t.pose_range, 0.0, 10.0)?;
        in_range("train.pseudo_zoom", t.pseudo_zoom, 0.0, 0.5)?;
        in_range("train.pseudo_rays", t.pseudo_rays, 0, 1 << 24)?;
        in_range("train.recorded_rays", t.recorded_rays, 0, 1 << 24)?;
        in_range("train.pseudo_per_step", t.pseudo_per_step, 1, 1 << 10)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::StudentTrainConfig;

    #[test]
    fn learning_rate_holds_then_decays_tenfold_per_decay_span() {
        let t = StudentTrainConfig {
            lr: 5e-4,
            lr_hold_steps: 100,
            lr_decay_steps: 50,
            ..StudentTrainConfig::default()
        };
        assert_eq!(t.learning_rate(0, 0.0), 5e-4);
        assert_eq!(t.learning_rate(100, 0.0), 5e-4);
        assert!((t.learning_rate(150, 0.0) - 5e-5).abs() < 1e-18);
        assert!((t.learning_rate(200, 0.0) - 5e-6).abs() < 1e-18);
        // Without a hold (the default) the decay starts at step 0.
        let plain = StudentTrainConfig {
            lr_hold_steps: 0,
            ..t
        };
        assert!((plain.learning_rate(50, 0.0) - 5e-5).abs() < 1e-18);
        // A time budget holds the rate for 60 % of the budget, then decays it tenfold over
        // the rest; the step schedule rules when it is further along.
        let timed = StudentTrainConfig {
            lr_decay_steps: 1_000_000,
            time_budget_s: 600.0,
            ..plain
        };
        let close = |a: f64, b: f64| (a - b).abs() < 1e-12;
        assert!(close(
            timed.learning_rate(10, 300.0),
            5e-4 * 0.1f64.powf(10.0 / 1e6)
        ));
        assert!(close(timed.learning_rate(10, 480.0), 5e-4 * 0.1f64.sqrt()));
        assert!(close(timed.learning_rate(0, 600.0), 5e-5));
        assert!(close(timed.learning_rate(0, 900.0), 5e-5));
        assert!(close(
            timed.learning_rate(500_000, 60.0),
            5e-4 * 0.1f64.sqrt()
        ));
    }
}
