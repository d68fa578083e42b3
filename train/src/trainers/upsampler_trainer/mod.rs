//! Training the learned upsampler ([`crate::networks::upsampler`]) over a trained student, which stays
//! fixed: the CNN learns from the full-size frames of the recorded views and from the
//! teacher's full-size renders of pseudo views (poses beyond the recording, drawn as the
//! student's own pseudo views are), on crops of the head's coarse box.
//!
//! A training crop is `crop + 2 halo` coarse rays on a side; the loss (mean squared error
//! of the composited pixels) counts only its central `crop x crop` rays' `r x r` blocks, so
//! that the zero padding at the crop's edge, which a rendered box only has on background,
//! teaches nothing.

mod config;
mod crops;

use std::path::{Path, PathBuf};

use candle_core::{Tensor, Var};
use candle_nn::VarMap;
use nldf_core::bounds::Bounds;
use nldf_core::camera::Camera;
use nldf_core::dataset::Frame;
use nldf_core::image::ImageRgb;
use nldf_core::run_files::{CONFIG_FILE, LOG_FILE, MODEL_FILE};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

pub use self::config::{UpsamplerRunConfig, UpsamplerTrainConfig};
use self::crops::{Crop, CropCutter, draw_crops};
use crate::error::{Error, Result};
use crate::networks::nn::{new_varmap, sorted_vars};
use crate::networks::upsampler::{Upsampler, render_upsampled, upsampler};
use crate::trainers::adam::{Adam, AdamParams};
use crate::trainers::checkpoint::{
    CheckpointParts, Clock, open_checkpoint, save_checkpoint, save_json,
};
use crate::trainers::config::read_config;
use crate::trainers::data::TrainData;
use crate::trainers::frame_model::{FrameModel, student_name};
use crate::trainers::log::CsvLog;
use crate::trainers::student_trainer::StudentModel;
use crate::trainers::teacher_trainer::TeacherModel;

/// A trained upsampler with its student.
pub struct UpsampledModel {
    pub dir: PathBuf,
    pub cfg: UpsamplerRunConfig,
    pub student: StudentModel,
    pub varmap: VarMap,
    pub up: Upsampler,
    pub step: usize,
    pub trained_s: f64,
}

impl UpsampledModel {
    /// The upsampler of `cfg` at step 0 over the student in `run`.
    fn build(dir: &Path, run: &Path, cfg: UpsamplerRunConfig) -> Result<UpsampledModel> {
        cfg.check()?;
        let student = StudentModel::open(&run.join(&cfg.student))?;
        let (varmap, vb) = new_varmap();
        let up = upsampler(&cfg.model, student.cfg.model.width, vb)?;
        Ok(UpsampledModel {
            dir: dir.to_path_buf(),
            cfg,
            student,
            varmap,
            up,
            step: 0,
            trained_s: 0.0,
        })
    }

    /// Whether `dir` holds a trained upsampler (its configuration and weights).
    pub fn is_upsampler(dir: &Path) -> bool {
        dir.join(MODEL_FILE).is_file()
            && read_config::<UpsamplerRunConfig>(&dir.join(CONFIG_FILE)).is_ok()
    }

    /// Loads the trained upsampler in `dir` (a folder of the run `run`) and its student.
    pub fn open(dir: &Path, run: &Path) -> Result<UpsampledModel> {
        let cfg: UpsamplerRunConfig = read_config(&dir.join(CONFIG_FILE))?;
        let mut model = Self::build(dir, run, cfg)?;
        let (step, clock) = open_checkpoint(dir, &model.varmap, None)?;
        (model.step, model.trained_s) = (step, clock.elapsed());
        Ok(model)
    }

    /// Renders one camera with one audio code (see [`render_upsampled`]); also returns the
    /// rays the student evaluated, coarse and the mouth patch's.
    pub fn render_view(
        &self,
        camera: &Camera,
        code: &Tensor,
        data: &TrainData,
    ) -> Result<(ImageRgb, usize)> {
        render_upsampled(
            &self.student.student,
            &self.up,
            camera,
            &data.dataset.background,
            code,
            &data.head_range(),
        )
    }
}

impl UpsampledModel {
    /// Starts training: draws the seeded weights, opens the run's teacher, finds the mouth
    /// patch when asked ([`UpsampledModel::find_mouth_patch`]) and writes `config.json`.
    fn start(&mut self, run: &Path, data: &TrainData) -> Result<(TeacherModel, Option<bool>)> {
        crate::networks::upsampler::init_upsampler_seeded(&self.varmap, self.cfg.train.seed)?;
        let teacher = TeacherModel::open(&nldf_core::run_files::teacher_dir(run))?;
        let mouth_found = self.find_mouth_patch(&teacher, data)?;
        std::fs::create_dir_all(&self.dir).map_err(|e| Error::io(&self.dir, e))?;
        save_json(&self.dir.join(CONFIG_FILE), &self.cfg)?;
        Ok((teacher, mouth_found))
    }

    /// With `train.mouth_patch`, finds the mouth's box ([`mouth_patch_box`]) and sets it as
    /// the model's; returns whether one was found (`None` when not asked).
    fn find_mouth_patch(
        &mut self,
        teacher: &TeacherModel,
        data: &TrainData,
    ) -> Result<Option<bool>> {
        if !self.cfg.train.mouth_patch {
            return Ok(None);
        }
        let mouth = mouth_patch_box(teacher, data)?;
        self.cfg.model.mouth_patch = mouth;
        self.up.cfg.mouth_patch = mouth;
        Ok(Some(mouth.is_some()))
    }
}

impl FrameModel for UpsampledModel {
    fn label(&self) -> String {
        self.dir
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "upsampler".into())
    }
    fn describe(&self) -> String {
        format!(
            "{} + upsampler x{}",
            student_name(&self.student.cfg),
            self.cfg.model.factor
        )
    }
    fn step(&self) -> usize {
        self.step
    }
    fn macs_per_ray(&self) -> f64 {
        // Per output ray that meets the head: the student's share of one coarse ray and the
        // CNN's per-pixel cost (an estimate: the box also holds pixels that miss).
        let r2 = (self.cfg.model.factor * self.cfg.model.factor) as f64;
        self.student.cfg.model.macs_per_ray() as f64 / r2
            + self.cfg.model.macs_per_pixel(self.student.cfg.model.width)
    }
    fn extra_macs(&self, data: &TrainData, frame: &Frame) -> f64 {
        let Some(mouth) = &self.cfg.model.mouth_patch else {
            return 0.0;
        };
        let camera = data.dataset.camera(frame);
        let patch =
            crate::networks::upsampler::mouth_patch_rays(&camera, &data.head_range(), mouth);
        patch.pixels.len() as f64 * self.student.cfg.model.macs_per_ray() as f64
    }
    fn render_frame(&self, data: &TrainData, frame: &Frame) -> Result<ImageRgb> {
        let code = self.student.audio_codes(data, &[frame.aud_id])?;
        Ok(self
            .render_view(&data.dataset.camera(frame), &code, data)?
            .0)
    }
}

/// The student alone on the coarse grid, upscaled bilinearly to the output's size: the
/// baseline the upsampler must beat at the same student cost.
pub struct CoarseBilinear {
    pub student: StudentModel,
    pub factor: usize,
}

impl FrameModel for CoarseBilinear {
    fn label(&self) -> String {
        format!("{}_bilinear_x{}", self.student.label(), self.factor)
    }
    fn describe(&self) -> String {
        format!(
            "{} at 1/{} side, bilinear",
            student_name(&self.student.cfg),
            self.factor
        )
    }
    fn step(&self) -> usize {
        self.student.step
    }
    fn macs_per_ray(&self) -> f64 {
        self.student.cfg.model.macs_per_ray() as f64 / (self.factor * self.factor) as f64
    }
    fn render_frame(&self, data: &TrainData, frame: &Frame) -> Result<ImageRgb> {
        let ds = &data.dataset;
        let camera = ds.camera(frame);
        let k = nldf_core::upsampler_config::coarse_intrinsics(&camera.intrinsics, self.factor)?;
        let coarse = Camera {
            intrinsics: k,
            c2w: camera.c2w,
        };
        let bg = ds.background.downscaled(self.factor as u32);
        let code = self.student.audio_codes(data, &[frame.aud_id])?;
        let small = self.student.render_view(&coarse, &bg, &code, data)?;
        Ok(small.upscaled(self.factor as u32))
    }
}

/// The upsampler's `report.json`: what its training run did ([`UpsamplerReport`]).
pub const REPORT_FILE: &str = "report.json";

/// What one training run produced.
#[derive(Debug, Clone, Serialize)]
pub struct UpsamplerReport {
    pub steps: usize,
    /// Seconds spent on the coarse features and the teacher's crops before the first step.
    pub prepare_s: f64,
    /// Seconds of optimizer steps.
    pub train_s: f64,
    pub final_loss: f64,
    pub recorded_views: usize,
    pub pseudo_crops: usize,
    /// Asked for a mouth patch (`train.mouth_patch`): whether a mouth box was found
    /// ([`mouth_patch_box`]); `None` when not asked.
    pub mouth_patch: Option<bool>,
}

/// Trains a new upsampler into `dir` over the student `cfg.student` of `run` and the
/// teacher `RUN/teacher`, on `data` (the data the student was trained on). `on_step` sees
/// each step and its loss. When `stop` is set (Ctrl-C) it checkpoints the steps done and
/// returns. It writes `config.json` first, then the checkpoint and [`REPORT_FILE`].
pub fn train_upsampler(
    dir: &Path,
    run: &Path,
    cfg: UpsamplerRunConfig,
    data: &TrainData,
    stop: &std::sync::atomic::AtomicBool,
    on_step: &mut dyn FnMut(usize, f64),
) -> Result<UpsamplerReport> {
    let mut model = UpsampledModel::build(dir, run, cfg)?;
    let (teacher, mouth_found) = model.start(run, data)?;
    let started = std::time::Instant::now();
    let t = model.cfg.train.clone();
    let r = model.cfg.model.factor;
    let side = t.crop + 2 * t.halo;
    let cutter = CropCutter {
        data,
        student: &model.student,
        t: &t,
        r,
        side,
        margin: model.cfg.model.margin,
        range: data.head_range(),
    };
    let mut rng = ChaCha8Rng::seed_from_u64(t.seed);
    let (recorded, pseudo) = cutter.prepare(&teacher, &mut rng)?;
    if recorded.is_empty() {
        return Err(Error::Config(format!(
            "no training frame's head box is {side} coarse rays on a side at factor {r}: \
             the frames are too small for this upsampler (lower `train.crop` or `halo`)"
        )));
    }
    let prepare_s = started.elapsed().as_secs_f64();
    let mut adam = upsampler_adam(&model.varmap)?;
    let mut log = CsvLog::open(&dir.join(LOG_FILE), 0)?;
    let clock = Clock::resumed(0.0);
    let mut last_loss = f64::NAN;
    let train_started = std::time::Instant::now();
    let mut done = 0;
    for step in 1..=t.iters {
        if stop.load(std::sync::atomic::Ordering::Relaxed) {
            break;
        }
        let crops = draw_crops(&recorded, &pseudo, data, &mut rng, &t, r)?;
        let (loss, lr) = train_step(&model.up, &mut adam, &crops, &t, r, step)?;
        last_loss = loss;
        if step % t.log_every == 0 || step == t.iters {
            let psnr = nldf_core::metrics::psnr_from_mse(last_loss);
            let n = t.crop * r;
            let px_per_s =
                (step * t.batch * n * n) as f64 / train_started.elapsed().as_secs_f64().max(1e-9);
            log.row(step, clock.elapsed(), last_loss, psnr, lr, px_per_s, None)?;
        }
        on_step(step, last_loss);
        done = step;
    }
    let train_s = train_started.elapsed().as_secs_f64();
    model.step = done;
    save_checkpoint(&CheckpointParts {
        dir,
        kind: "upsampler",
        step: done,
        elapsed: clock.elapsed(),
        varmap: &model.varmap,
        adam: &adam,
        title: "upsampler",
    })?;
    let report = UpsamplerReport {
        steps: done,
        prepare_s,
        train_s,
        final_loss: last_loss,
        recorded_views: recorded.len(),
        pseudo_crops: pseudo.len(),
        mouth_patch: mouth_found,
    };
    save_json(&dir.join(REPORT_FILE), &report)?;
    Ok(report)
}

/// The mouth's box grows by this share of its size on every side: the training frames'
/// mouths span only the openings the recording holds, and a new voice opens it otherwise.
/// Measured on the standard head at 256 x 256 (seed 0, 12 `novel` frames; docs/sharp.md,
/// "The mouth patch"): growths of 0, 0.05 and 0.15 gave the same mouth PSNR within 0.004
/// dB, with 1202, 1455 and 2036 patch rays a frame at the default pose.
pub const MOUTH_PATCH_PAD: f32 = 0.05;

/// Share of the mouth's surface points left out at each end of every axis, so that a few
/// points the teacher places off the face (a silhouette's edge) do not stretch the box.
const MOUTH_PATCH_TRIM: f64 = 0.01;

/// The mouth's box for an upsampler's mouth patch ([`UpsamplerConfig::mouth_patch`]): the
/// training frames' mouth pixels carried to the head's surface by the teacher
/// ([`mouth_surface_points`]), their box between the 1st and 99th percentile on each axis,
/// grown by [`MOUTH_PATCH_PAD`] and clipped to the head's bounds. `None` when the frames
/// have no mouth region (no labels, no landmarks), when the teacher holds no surface at
/// their mouth pixels (its weights there sum below one half: an undertrained teacher), or
/// when the box falls outside the head.
///
/// [`UpsamplerConfig::mouth_patch`]: nldf_core::upsampler_config::UpsamplerConfig::mouth_patch
/// [`mouth_surface_points`]: crate::trainers::views::mouth_surface_points
pub fn mouth_patch_box(teacher: &TeacherModel, data: &TrainData) -> Result<Option<Bounds>> {
    let points: Vec<glam::Vec3> = crate::trainers::views::mouth_surface_points(teacher, data)?
        .into_iter()
        .flatten()
        .filter(|p| p.is_finite())
        .collect();
    if points.is_empty() {
        return Ok(None);
    }
    let (mut lo, mut hi) = (glam::Vec3::ZERO, glam::Vec3::ZERO);
    for a in 0..3 {
        let mut v: Vec<f32> = points.iter().map(|p| p[a]).collect();
        v.sort_by(f32::total_cmp);
        let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
        (lo[a], hi[a]) = (at(MOUTH_PATCH_TRIM), at(1.0 - MOUTH_PATCH_TRIM));
    }
    let grown = Bounds { lo, hi }.padded(MOUTH_PATCH_PAD);
    let head = data.head_range().bounds;
    let clipped = Bounds {
        lo: grown.lo.max(head.lo),
        hi: grown.hi.min(head.hi),
    };
    Ok((0..3)
        .all(|a| clipped.lo[a] < clipped.hi[a])
        .then_some(clipped))
}

/// Gives the trained upsampler in `dir` (a folder of `run`) a mouth patch: finds the
/// mouth's box from the run's teacher on `data` ([`mouth_patch_box`]) and rewrites the
/// upsampler's `config.json` with it (atomically); the weights stay as they are. Returns
/// the box, `None` (and the file untouched) when the data has no mouth region.
pub fn attach_mouth_patch(dir: &Path, run: &Path, data: &TrainData) -> Result<Option<Bounds>> {
    let path = dir.join(CONFIG_FILE);
    let mut cfg: UpsamplerRunConfig = read_config(&path)?;
    let teacher = TeacherModel::open(&nldf_core::run_files::teacher_dir(run))?;
    let mouth = mouth_patch_box(&teacher, data)?;
    if mouth.is_some() {
        cfg.model.mouth_patch = mouth;
        cfg.train.mouth_patch = true;
        cfg.check()?;
        save_json(&path, &cfg)?;
    }
    Ok(mouth)
}

/// Adam over every upsampler weight at the same learning rate.
fn upsampler_adam(varmap: &VarMap) -> Result<Adam> {
    let vars: Vec<(String, Var, f64)> = sorted_vars(varmap)?
        .into_iter()
        .map(|(n, v)| (n, v, 1.0))
        .collect();
    Ok(Adam::new(
        vars,
        AdamParams {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
        },
    ))
}

/// One optimizer step of the upsampler on `crops` (step `step` of the schedule): the
/// composited pixels' mean squared error against the targets over the crops' centres.
/// Returns the loss and the learning rate it stepped with.
fn train_step(
    up: &Upsampler,
    adam: &mut Adam,
    crops: &[Crop],
    t: &UpsamplerTrainConfig,
    r: usize,
    step: usize,
) -> Result<(f64, f64)> {
    let grid = Tensor::stack(&crops.iter().map(|c| &c.grid).collect::<Vec<_>>(), 0)?;
    let target = Tensor::stack(&crops.iter().map(|c| &c.target).collect::<Vec<_>>(), 0)?;
    let bg = Tensor::stack(&crops.iter().map(|c| &c.background).collect::<Vec<_>>(), 0)?;
    let out = up.forward(&grid)?;
    let (lo, n) = (t.halo * r, t.crop * r);
    let out = out.narrow(2, lo, n)?.narrow(3, lo, n)?;
    let pixels = Upsampler::composite(&out, &bg)?;
    let loss = (pixels - target)?.sqr()?.mean_all()?;
    let grads = loss.backward()?;
    let frac = (step - 1) as f64 / t.iters.max(2).saturating_sub(1) as f64;
    let lr = t.lr * (t.lr_final / t.lr).powf(frac);
    adam.step(&grads, lr)?;
    let loss = loss.to_scalar::<f32>()? as f64;
    if !loss.is_finite() {
        return Err(Error::NonFinite(format!(
            "the upsampler's loss became {loss} at step {step}"
        )));
    }
    Ok((loss, lr))
}
