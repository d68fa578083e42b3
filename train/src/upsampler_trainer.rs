//! Training the learned upsampler ([`crate::upsampler`]) over a trained student, which stays
//! fixed: the CNN learns from the full-size frames of the recorded views and from the
//! teacher's full-size renders of pseudo views (poses beyond the recording, drawn as the
//! student's own pseudo views are), on crops of the head's coarse box.
//!
//! A training crop is `crop + 2 halo` coarse rays on a side; the loss (mean squared error
//! of the composited pixels) counts only its central `crop x crop` rays' `r x r` blocks, so
//! that the zero padding at the crop's edge, which a rendered box only has on background,
//! teaches nothing.

use std::path::{Path, PathBuf};

use candle_core::{Device, Tensor, Var};
use candle_nn::VarMap;
use nldf_core::bounds::HeadRange;
use nldf_core::camera::Camera;
use nldf_core::dataset::Frame;
use nldf_core::image::ImageRgb;
use nldf_core::rays::rays_for_pixels;
use nldf_core::run_files::{CONFIG_FILE, LOG_FILE, MODEL_FILE};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::adam::{Adam, AdamParams};
use crate::checkpoint::{CheckpointParts, Clock, open_checkpoint, save_checkpoint, save_json};
use crate::config::read_config;
use crate::data::TrainData;
use crate::error::{Error, Result};
use crate::eval::FrameModel;
use crate::log::CsvLog;
use crate::nn::{new_varmap, sorted_vars};
use crate::student_trainer::StudentModel;
use crate::teacher_trainer::TeacherModel;
use crate::upsampler::{
    CoarseBox, Upsampler, UpsamplerConfig, coarse_box_features, image_box, render_upsampled,
    upsampler,
};
use crate::views::{View, training_views};

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
    /// coarse rays the student evaluated.
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
            crate::eval::student_name(&self.student.cfg),
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
            crate::eval::student_name(&self.student.cfg),
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

/// One training crop: the coarse input `[C, s, s]` (`s = crop + 2 halo`) and, for the
/// central `crop r` pixels on a side, the target and the background, `[3, crop r, crop r]`.
#[derive(Clone)]
struct Crop {
    grid: Tensor,
    target: Tensor,
    background: Tensor,
}

/// A recorded view's coarse box and its frame, from which crops are cut at each step.
struct RecordedView {
    coarse: CoarseBox,
    image: usize,
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
    crate::upsampler::init_upsampler_seeded(&model.varmap, model.cfg.train.seed)?;
    let teacher = TeacherModel::open(&nldf_core::run_files::teacher_dir(run))?;
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    save_json(&dir.join(CONFIG_FILE), &model.cfg)?;
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
    };
    save_json(&dir.join(REPORT_FILE), &report)?;
    Ok(report)
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

/// One step's batch of crops: the pseudo views' share (`pseudo_fraction`, when there
/// are any) drawn from `pseudo`, the rest cut from random recorded views.
fn draw_crops(
    recorded: &[RecordedView],
    pseudo: &[Crop],
    data: &TrainData,
    rng: &mut ChaCha8Rng,
    t: &UpsamplerTrainConfig,
    r: usize,
) -> Result<Vec<Crop>> {
    let n_pseudo_step = if pseudo.is_empty() {
        0
    } else {
        ((t.batch as f64 * t.pseudo_fraction).round() as usize).min(t.batch)
    };
    let mut crops = Vec::with_capacity(t.batch);
    for b in 0..t.batch {
        if b < n_pseudo_step {
            crops.push(pseudo[rng.random_range(0..pseudo.len())].clone());
        } else {
            let v = &recorded[rng.random_range(0..recorded.len())];
            let mouth = rng.random::<f64>() < t.mouth_fraction;
            crops.push(recorded_crop(v, data, rng, mouth, t, r)?);
        }
    }
    Ok(crops)
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

/// What cutting the training crops reads: the data, the fixed student and the crops'
/// geometry.
struct CropCutter<'a> {
    data: &'a TrainData,
    student: &'a StudentModel,
    t: &'a UpsamplerTrainConfig,
    /// The upsampler's factor.
    r: usize,
    /// Coarse rays on a crop's side, halo included.
    side: usize,
    /// Coarse rays around the hits in a coarse box.
    margin: usize,
    range: HeadRange,
}

impl CropCutter<'_> {
    /// The recorded views' coarse boxes, then the crops the teacher renders once of the
    /// pseudo views.
    fn prepare(
        &self,
        teacher: &TeacherModel,
        rng: &mut ChaCha8Rng,
    ) -> Result<(Vec<RecordedView>, Vec<Crop>)> {
        let student = self.student;
        // Recorded views: the coarse box of every training frame.
        let views = training_views(
            self.data,
            &student.cfg.train,
            student.cfg.model.anchor_beams,
        );
        let mut recorded = Vec::new();
        for (vi, view) in views.iter().filter(|v| v.recorded).enumerate() {
            if let Some(coarse) = self.coarse_of(view)? {
                recorded.push(RecordedView { coarse, image: vi });
            }
        }
        // Pseudo views: crops the teacher renders once.
        let mut pseudo = Vec::new();
        let pseudo_views: Vec<_> = views.iter().filter(|v| !v.recorded).collect();
        let n_pseudo = self.t.pseudo_views.min(pseudo_views.len());
        for k in 0..n_pseudo {
            let view = pseudo_views[k * pseudo_views.len() / n_pseudo.max(1)];
            let Some(coarse) = self.coarse_of(view)? else {
                continue;
            };
            self.pseudo_crops(teacher, view, &coarse, rng, &mut pseudo)?;
        }
        Ok((recorded, pseudo))
    }

    /// A view's coarse box, when it holds a hit and a whole crop.
    fn coarse_of(&self, view: &View) -> Result<Option<CoarseBox>> {
        let (student, side) = (self.student, self.side);
        let code = student.audio_codes(self.data, &[view.aud_id])?;
        let coarse = coarse_box_features(
            &student.student,
            &view.camera,
            &code,
            &self.range,
            (self.r, self.margin),
        )?;
        let (bh, bw) = (coarse.rows.1 - coarse.rows.0, coarse.cols.1 - coarse.cols.0);
        Ok((coarse.any_hit && bh >= side && bw >= side).then_some(coarse))
    }

    /// Cuts `pseudo_crops` random crops of a pseudo view's coarse box into `crops`, their
    /// targets rendered by the teacher.
    fn pseudo_crops(
        &self,
        teacher: &TeacherModel,
        view: &View,
        coarse: &CoarseBox,
        rng: &mut ChaCha8Rng,
        crops: &mut Vec<Crop>,
    ) -> Result<()> {
        let (t, r, side) = (self.t, self.r, self.side);
        let ds = &self.data.dataset;
        let (bh, bw) = (coarse.rows.1 - coarse.rows.0, coarse.cols.1 - coarse.cols.0);
        let teacher_code = teacher.audio_codes(self.data, &[view.aud_id])?;
        for _ in 0..t.pseudo_crops {
            let (y, x) = (
                rng.random_range(0..=bh - side),
                rng.random_range(0..=bw - side),
            );
            let grid = coarse
                .grid
                .narrow(2, y, side)?
                .narrow(3, x, side)?
                .squeeze(0)?;
            // The central rays' blocks in output pixels.
            let row0 = (coarse.rows.0 + y + t.halo) * r;
            let col0 = (coarse.cols.0 + x + t.halo) * r;
            let n = t.crop * r;
            let pixels: Vec<(u32, u32)> = (0..n * n)
                .map(|p| ((col0 + p % n) as u32, (row0 + p / n) as u32))
                .collect();
            let bg: Vec<f32> = pixels
                .iter()
                .flat_map(|&(i, j)| ds.background.get(i, j))
                .collect();
            let rays = rays_for_pixels(&view.camera, &pixels);
            let colours = teacher.teacher.render_eval(
                &rays,
                &bg,
                &teacher_code,
                &self.range,
                teacher.teacher.cfg.min_transmittance,
            )?;
            let planar = |v: &[f32]| -> Result<Tensor> {
                Ok(Tensor::from_vec(v.to_vec(), (n, n, 3), &Device::Cpu)?
                    .permute((2, 0, 1))?
                    .contiguous()?)
            };
            crops.push(Crop {
                grid,
                target: planar(&colours)?,
                background: planar(&bg)?,
            });
        }
        Ok(())
    }
}

/// A random crop of a recorded view, its target from the frame itself; with `mouth`, one
/// whose loss-counted centre holds a random pixel of the frame's mouth region (when it has
/// one).
fn recorded_crop(
    v: &RecordedView,
    data: &TrainData,
    rng: &mut ChaCha8Rng,
    mouth: bool,
    t: &UpsamplerTrainConfig,
    r: usize,
) -> Result<Crop> {
    let (halo, crop) = (t.halo, t.crop);
    let side = crop + 2 * halo;
    let c = &v.coarse;
    let (bh, bw) = (c.rows.1 - c.rows.0, c.cols.1 - c.cols.0);
    let mouth_pixels = &data.mouth_pixels[v.image];
    let (y, x) = if mouth && !mouth_pixels.is_empty() {
        let (i, j) = mouth_pixels[rng.random_range(0..mouth_pixels.len())];
        // The crop's top-left so that coarse ray (i / r, j / r) falls in its centre.
        let mut place = |at: usize, lo: usize, n: usize| -> usize {
            let shift = rng.random_range(0..crop);
            at.saturating_sub(lo + halo + shift).min(n - side)
        };
        let y = place(j as usize / r, c.rows.0, bh);
        let x = place(i as usize / r, c.cols.0, bw);
        (y, x)
    } else {
        (
            rng.random_range(0..=bh - side),
            rng.random_range(0..=bw - side),
        )
    };
    let grid = c.grid.narrow(2, y, side)?.narrow(3, x, side)?.squeeze(0)?;
    let row0 = (c.rows.0 + y + halo) * r;
    let col0 = (c.cols.0 + x + halo) * r;
    let n = crop * r;
    let rows = (row0, row0 + n);
    let cols = (col0, col0 + n);
    Ok(Crop {
        grid,
        target: image_box(&data.images[v.image], rows, cols)?.squeeze(0)?,
        background: image_box(&data.dataset.background, rows, cols)?.squeeze(0)?,
    })
}
