//! Held-out evaluation: renders a split's frames with a trained model, scores them (PSNR,
//! SSIM, mouth-region PSNR), and writes the renders, a side-by-side grid (ground truth |
//! render | error heat map) and `metrics.json`.

use std::path::{Path, PathBuf};

use nldf_core::dataset::Split;
use nldf_core::image::{ImageRgb, error_map, grid};
use nldf_core::metrics::{psnr, ssim};
use serde::Serialize;

use crate::checkpoint::save_json;
use crate::error::{Error, Result};
use crate::trainer::{TeacherRun, TrainData, region_psnrs};

/// Scores of one frame.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FrameScore {
    pub img_id: i64,
    pub psnr: f64,
    pub ssim: f64,
    pub face_psnr: Option<f64>,
    pub mouth_psnr: Option<f64>,
}

/// The result of evaluating one model on one split.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EvalReport {
    pub model: String,
    pub split: String,
    pub step: usize,
    pub frames: Vec<FrameScore>,
    pub psnr: f64,
    pub ssim: f64,
    pub face_psnr: Option<f64>,
    pub mouth_psnr: Option<f64>,
    /// Seconds spent rendering, per frame.
    pub render_s_per_frame: f64,
    /// Files written.
    pub files: Vec<PathBuf>,
}

/// Rows of the side-by-side grid.
const GRID_ROWS: usize = 4;
/// Gain of the error heat map (an absolute error of 0.25 is full scale).
const ERROR_GAIN: f32 = 4.0;

/// Evaluates the teacher of `run` on `split` (at most `max_frames`, spread evenly), writing
/// into `out`: `teacher/<img_id>.png`, `grid.png` and `metrics.json`. `on_frame` is called
/// after each rendered frame.
pub fn eval_teacher(
    run: &TeacherRun,
    data: &TrainData,
    split: Split,
    max_frames: Option<usize>,
    out: &Path,
    on_frame: &mut dyn FnMut(),
) -> Result<EvalReport> {
    let all = data.dataset.frames(split);
    if all.is_empty() {
        return Err(Error::Config(format!("the {split:?} split has no frames")));
    }
    let n = max_frames.unwrap_or(all.len()).clamp(1, all.len());
    let frames: Vec<_> = (0..n).map(|k| &all[k * all.len() / n]).collect();
    let render_dir = out.join("teacher");
    std::fs::create_dir_all(&render_dir).map_err(|e| Error::io(&render_dir, e))?;
    let mut scores = Vec::with_capacity(n);
    let mut rows: Vec<Vec<ImageRgb>> = Vec::new();
    let mut files = Vec::new();
    let mut render_s = 0.0;
    for (k, frame) in frames.iter().enumerate() {
        let started = std::time::Instant::now();
        let render = run.render_frame(data, frame)?;
        render_s += started.elapsed().as_secs_f64();
        let truth = data.dataset.load_image(frame)?;
        let regions = data.dataset.load_regions(frame)?;
        let (face, mouth) = match &regions {
            Some(r) => region_psnrs(&render, &truth, r)?,
            None => (None, None),
        };
        scores.push(FrameScore {
            img_id: frame.img_id,
            psnr: psnr(&render, &truth)?,
            ssim: ssim(&render, &truth)?,
            face_psnr: face,
            mouth_psnr: mouth,
        });
        let path = render_dir.join(format!("{}.png", frame.img_id));
        render.save_png(&path)?;
        files.push(path);
        if k * GRID_ROWS / n != (k + 1) * GRID_ROWS / n || n <= GRID_ROWS {
            let err = error_map(&render, &truth, ERROR_GAIN)?;
            rows.push(vec![truth, render, err]);
        }
        on_frame();
    }
    let grid_path = out.join("grid.png");
    grid(&rows, 2, [1.0; 3]).save_png(&grid_path)?;
    files.push(grid_path);
    let finite_mean = |v: Vec<f64>| {
        let v: Vec<f64> = v.into_iter().filter(|x| x.is_finite()).collect();
        (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
    };
    let report = EvalReport {
        model: format!(
            "teacher {}x{} ({} samples/ray)",
            run.cfg.model.depth, run.cfg.model.width, run.cfg.model.n_samples
        ),
        split: format!("{split:?}").to_lowercase(),
        step: run.step,
        psnr: finite_mean(scores.iter().map(|s| s.psnr).collect()).unwrap_or(f64::INFINITY),
        ssim: finite_mean(scores.iter().map(|s| s.ssim).collect()).unwrap_or(1.0),
        face_psnr: finite_mean(scores.iter().filter_map(|s| s.face_psnr).collect()),
        mouth_psnr: finite_mean(scores.iter().filter_map(|s| s.mouth_psnr).collect()),
        render_s_per_frame: render_s / n as f64,
        frames: scores,
        files: {
            let mut f = files;
            f.push(out.join("metrics.json"));
            f
        },
    };
    save_json(&out.join("metrics.json"), &report)?;
    Ok(report)
}
