//! Held-out evaluation: renders a split's frames with trained models (the teacher, the
//! student), scores them (PSNR, SSIM, head- and mouth-region PSNR), and writes the renders,
//! a side-by-side grid (ground truth | each model's render and error heat map) and
//! `metrics.json`.

use std::path::{Path, PathBuf};

use nldf_core::dataset::{Dataset, Split};
use nldf_core::image::{ImageRgb, error_map, grid};
use serde::Serialize;

use crate::error::{Error, Result};
use crate::trainers::checkpoint::save_json;
use crate::trainers::data::TrainData;
pub use crate::trainers::frame_model::{FrameModel, student_name, student_short_name};
use crate::trainers::scores::frame_scores;
use crate::trainers::student_trainer::StudentModel;
use crate::trainers::teacher_trainer::TeacherModel;
use nldf_core::dataset::Frame;
use nldf_core::region::Region;

/// Rays of a frame that hit the head's bounds.
fn hit_rays(data: &TrainData, frame: &Frame) -> usize {
    let ds = &data.dataset;
    nldf_core::rays::head_rays(&ds.camera(frame), &data.head_range())
        .pixels
        .len()
}

impl FrameModel for TeacherModel {
    fn label(&self) -> String {
        "teacher".into()
    }
    fn describe(&self) -> String {
        let m = &self.cfg.model;
        format!(
            "{} {}x{} ({} samples/ray)",
            m.kind_name(),
            m.depth,
            m.width,
            m.n_samples + m.n_importance
        )
    }
    fn step(&self) -> usize {
        self.step
    }
    fn macs_per_ray(&self) -> f64 {
        self.cfg.model.macs_per_ray() as f64
    }
    fn render_frame(&self, data: &TrainData, frame: &Frame) -> Result<ImageRgb> {
        TeacherModel::render_frame(self, data, frame)
    }
}

impl FrameModel for StudentModel {
    fn label(&self) -> String {
        self.dir
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "student".into())
    }
    fn describe(&self) -> String {
        student_name(&self.cfg)
    }
    fn step(&self) -> usize {
        self.step
    }
    fn macs_per_ray(&self) -> f64 {
        self.cfg.model.macs_per_ray() as f64
    }
    fn render_frame(&self, data: &TrainData, frame: &Frame) -> Result<ImageRgb> {
        StudentModel::render_frame(self, data, frame)
    }
}

/// Scores of one frame.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FrameScore {
    pub img_id: i64,
    pub psnr: f64,
    pub ssim: f64,
    pub head_psnr: Option<f64>,
    pub head_ssim: Option<f64>,
    pub mouth_psnr: Option<f64>,
    /// Share of the pixels outside the head whose colour differs from the background
    /// ([`repainted_share`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub repainted: Option<f64>,
    /// What the view is, for a synthetic scene's evaluation splits (see
    /// [`nldf_core::synth::eval_views`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub view: Option<String>,
}

/// Mean scores of the frames of one kind of view of a synthetic scene's evaluation split
/// (`novel`: `turned 1.5x`, `closer`, `farther`; `sweep`: each turn), which the whole
/// split's mean hides.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ViewScore {
    pub view: String,
    pub frames: usize,
    pub psnr: f64,
    pub head_psnr: Option<f64>,
    pub mouth_psnr: Option<f64>,
}

/// The result of evaluating one model on one split.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EvalReport {
    /// What the model is, for tables.
    pub model: String,
    /// The folder of its renders in the evaluation's output.
    pub label: String,
    pub split: String,
    pub step: usize,
    pub frames: Vec<FrameScore>,
    pub psnr: f64,
    pub ssim: f64,
    /// PSNR inside the head: the headline (the whole frame counts copied background).
    pub head_psnr: Option<f64>,
    pub head_ssim: Option<f64>,
    pub mouth_psnr: Option<f64>,
    /// Mean share of the pixels outside the head that differ from the background
    /// ([`repainted_share`]).
    pub repainted: Option<f64>,
    /// Seconds spent rendering, per frame.
    pub render_s_per_frame: f64,
    /// Network multiply-adds per frame, on average (rays that miss the head cost none).
    pub macs_per_frame: f64,
    /// Frames whose render holds a NaN or infinite value. Their scores are NaN, so the
    /// means are too: an evaluation with any is a failure, not a score.
    pub non_finite_frames: usize,
    /// The means per kind of view, in the split's order; empty when the frames carry none.
    pub by_view: Vec<ViewScore>,
}

/// Everything one evaluation wrote.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Evaluation {
    pub models: Vec<EvalReport>,
    /// Files written.
    pub files: Vec<PathBuf>,
}

/// Rows of the side-by-side grid.
const GRID_ROWS: usize = 4;
/// Gain of the error heat map (an absolute error of 0.25 is full scale).
const ERROR_GAIN: f32 = 4.0;

/// Evaluates `models` on `split` (at most `max_frames`, spread evenly over each kind of
/// view: [`pick_frames`]), writing into
/// `out`: `<label>/<img_id>.png` per model, `grid.png` (ground truth, then each model's
/// render and error map) and `metrics.json`. `on_frame` is called after each frame.
pub fn eval_models(
    models: &[&dyn FrameModel],
    data: &TrainData,
    split: Split,
    max_frames: Option<usize>,
    out: &Path,
    on_frame: &mut dyn FnMut(),
) -> Result<Evaluation> {
    eval_models_against(models, data, None, split, max_frames, out, on_frame)
}

/// [`eval_models`], each frame scored against `against`'s frame of the same `img_id` in
/// the same split (its image and its regions: head, mouth, background) instead of the
/// rendered dataset's own, when given. The models still render `data`'s cameras and
/// composite over `data`'s background. Two runs trained on different datasets of one scene
/// (a prepared video and the scene it was made from) are then scored on the same pixels.
/// Errors when `against` lacks one of the frames.
pub fn eval_models_against(
    models: &[&dyn FrameModel],
    data: &TrainData,
    against: Option<&Dataset>,
    split: Split,
    max_frames: Option<usize>,
    out: &Path,
    on_frame: &mut dyn FnMut(),
) -> Result<Evaluation> {
    let (frames, views) = frames_to_score(data, split, max_frames)?;
    let n = frames.len();
    let mut scores: Vec<Vec<FrameScore>> = vec![Vec::with_capacity(n); models.len()];
    let mut render_s = vec![0.0; models.len()];
    let mut macs = vec![0.0; models.len()];
    let mut non_finite = vec![0usize; models.len()];
    let mut rows: Vec<Vec<ImageRgb>> = Vec::new();
    let mut files = Vec::new();
    for m in models {
        let dir = out.join(m.label());
        std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
    }
    for (k, frame) in frames.iter().enumerate() {
        let (truth, regions) = ground_truth(&data.dataset, against, split, frame)?;
        let in_grid = k * GRID_ROWS / n != (k + 1) * GRID_ROWS / n || n <= GRID_ROWS;
        let mut row = vec![truth.clone()];
        let hits = hit_rays(data, frame) as f64;
        for (mi, model) in models.iter().enumerate() {
            let started = std::time::Instant::now();
            let render = model.render_frame(data, frame)?;
            render_s[mi] += started.elapsed().as_secs_f64();
            macs[mi] += hits * model.macs_per_ray() + model.extra_macs(data, frame);
            let view = views.get(&frame.img_id).cloned();
            let background = &data.dataset.background;
            let score = score_frame(&render, &truth, regions.as_deref(), background, frame, view)?;
            non_finite[mi] += usize::from(render.non_finite_values() > 0);
            scores[mi].push(score);
            let path = out
                .join(model.label())
                .join(format!("{}.png", frame.img_id));
            render.save_png(&path)?;
            files.push(path);
            if in_grid {
                let err = error_map(&render, &truth, ERROR_GAIN)?;
                row.push(render);
                row.push(err);
            }
        }
        if in_grid {
            rows.push(row);
        }
        on_frame();
    }
    let grid_path = out.join("grid.png");
    grid(&rows, 2, [1.0; 3]).save_png(&grid_path)?;
    files.push(grid_path);
    let totals = ModelTotals {
        render_s,
        macs,
        non_finite,
    };
    let reports = model_reports(models, split, scores, &totals, n);
    files.push(out.join("metrics.json"));
    let evaluation = Evaluation {
        models: reports,
        files,
    };
    save_json(&out.join("metrics.json"), &evaluation)?;
    Ok(evaluation)
}

/// The image and regions `frame` is scored against: its own, or those of `against`'s
/// frame of the same `img_id` in `split`.
fn ground_truth(
    own: &Dataset,
    against: Option<&Dataset>,
    split: Split,
    frame: &Frame,
) -> Result<(ImageRgb, Option<Vec<Region>>)> {
    let (ds, frame) = match against {
        None => (own, frame),
        Some(ds) => {
            let twin = ds.frames(split).iter().find(|f| f.img_id == frame.img_id);
            let twin = twin.ok_or_else(|| {
                Error::invalid(
                    &ds.root,
                    format!(
                        "has no frame {} in its {} split to score against",
                        frame.img_id,
                        split.name()
                    ),
                )
            })?;
            (ds, twin)
        }
    };
    Ok((ds.load_image(frame)?, ds.load_regions(frame)?))
}

/// What each kind of view of a split is called, by `img_id` (empty without a scene file).
type Views = std::collections::HashMap<i64, String>;

/// The frames of `split` that [`eval_models`] scores (at most `max_frames`: [`pick_frames`])
/// and the kinds of view of the split's frames.
fn frames_to_score(
    data: &TrainData,
    split: Split,
    max_frames: Option<usize>,
) -> Result<(Vec<&Frame>, Views)> {
    let all = data.dataset.frames(split);
    if all.is_empty() {
        return Err(Error::Config(format!(
            "the {} split of {} has no frames",
            split.name(),
            data.dataset.root.display()
        )));
    }
    let views = nldf_core::synth::eval_views(&data.dataset.root, split.name())?;
    let kinds: Vec<Option<&str>> = all
        .iter()
        .map(|f| views.get(&f.img_id).map(String::as_str))
        .collect();
    let picked = pick_frames(&kinds, max_frames.unwrap_or(all.len()));
    Ok((picked.iter().map(|&i| &all[i]).collect(), views))
}

/// Indices of at most `n` (at least 1; none of no frames) of the frames whose kinds of view
/// are `kinds`, in order, spread evenly over each kind in turn. The kinds take shares of `n`
/// in proportion to their frames, the earliest kinds the remainder. Spreading over the whole split instead
/// would alias with the split's own pattern: `novel` cycles turned, closer, farther, so
/// every third of its 84 frames is the turned view alone. Frames without a kind form one
/// kind, so a split without views is spread as a whole.
pub fn pick_frames(kinds: &[Option<&str>], n: usize) -> Vec<usize> {
    let mut groups: Vec<(Option<&str>, Vec<usize>)> = Vec::new();
    for (i, kind) in kinds.iter().enumerate() {
        match groups.iter_mut().find(|(k, _)| k == kind) {
            Some((_, members)) => members.push(i),
            None => groups.push((*kind, vec![i])),
        }
    }
    let total = kinds.len();
    if total == 0 {
        return Vec::new();
    }
    let n = n.clamp(1, total);
    let mut quotas: Vec<usize> = groups.iter().map(|(_, g)| n * g.len() / total).collect();
    let mut left = n - quotas.iter().sum::<usize>();
    for (quota, (_, g)) in quotas.iter_mut().zip(&groups) {
        if left > 0 && *quota < g.len() {
            *quota += 1;
            left -= 1;
        }
    }
    let mut picked: Vec<usize> = groups
        .iter()
        .zip(&quotas)
        .flat_map(|((_, g), &q)| (0..q).map(move |k| g[k * g.len() / q]))
        .collect();
    picked.sort_unstable();
    picked
}

/// Per model, what an evaluation sums over the frames besides their scores.
struct ModelTotals {
    /// Seconds spent rendering.
    render_s: Vec<f64>,
    /// Network multiply-adds.
    macs: Vec<f64>,
    /// Frames whose render holds a NaN or infinite value.
    non_finite: Vec<usize>,
}

/// The reports of `models` on `split` from their frames' `scores` and `totals` over `n`
/// frames.
fn model_reports(
    models: &[&dyn FrameModel],
    split: Split,
    scores: Vec<Vec<FrameScore>>,
    totals: &ModelTotals,
    n: usize,
) -> Vec<EvalReport> {
    models
        .iter()
        .zip(scores)
        .enumerate()
        .map(|(mi, (model, scores))| EvalReport {
            model: model.describe(),
            label: model.label(),
            split: split.name().into(),
            step: model.step(),
            psnr: mean(scores.iter().map(|s| s.psnr).collect()).unwrap_or(f64::NAN),
            ssim: mean(scores.iter().map(|s| s.ssim).collect()).unwrap_or(f64::NAN),
            head_psnr: mean(scores.iter().filter_map(|s| s.head_psnr).collect()),
            head_ssim: mean(scores.iter().filter_map(|s| s.head_ssim).collect()),
            mouth_psnr: mean(scores.iter().filter_map(|s| s.mouth_psnr).collect()),
            repainted: mean(scores.iter().filter_map(|s| s.repainted).collect()),
            render_s_per_frame: totals.render_s[mi] / n as f64,
            macs_per_frame: totals.macs[mi] / n as f64,
            non_finite_frames: totals.non_finite[mi],
            by_view: by_view(&scores),
            frames: scores,
        })
        .collect()
}

/// The scores of one render of `frame` against its ground truth `truth`, `view` the kind
/// of view it is.
fn score_frame(
    render: &ImageRgb,
    truth: &ImageRgb,
    regions: Option<&[Region]>,
    background: &ImageRgb,
    frame: &Frame,
    view: Option<String>,
) -> Result<FrameScore> {
    let f = frame_scores(render, truth, regions)?;
    let repainted = regions.and_then(|r| repainted_share(render, background, r));
    Ok(FrameScore {
        img_id: frame.img_id,
        psnr: f.psnr,
        ssim: f.ssim,
        head_psnr: f.head_psnr,
        head_ssim: f.head_ssim,
        mouth_psnr: f.mouth_psnr,
        repainted,
        view,
    })
}

/// A colour change from the background above this (in [0, 1] units, 1.5/255) counts
/// as repainting it.
pub const REPAINT_THRESHOLD: f32 = 1.5 / 255.0;

/// The share of the pixels outside the head (by `regions`) whose colour in `render`
/// differs from `background` by more than [`REPAINT_THRESHOLD`] in any channel: how much
/// of the background a model painted over instead of keeping. `None` when the frame has no
/// pixel outside the head or the sizes differ.
pub fn repainted_share(
    render: &ImageRgb,
    background: &ImageRgb,
    regions: &[Region],
) -> Option<f64> {
    if render.data.len() != background.data.len() || 3 * regions.len() != render.data.len() {
        return None;
    }
    let (mut outside, mut changed) = (0usize, 0usize);
    for (p, region) in regions.iter().enumerate() {
        if region.is_head() {
            continue;
        }
        outside += 1;
        let (a, b) = (
            &render.data[3 * p..3 * p + 3],
            &background.data[3 * p..3 * p + 3],
        );
        // A NaN counts as changed.
        if a.iter()
            .zip(b)
            .any(|(x, y)| (x - y).abs() > REPAINT_THRESHOLD || (x - y).is_nan())
        {
            changed += 1;
        }
    }
    (outside > 0).then(|| changed as f64 / outside as f64)
}

/// The plain mean, `None` of nothing: a NaN frame makes its model's mean NaN instead of
/// dropping out.
fn mean(v: Vec<f64>) -> Option<f64> {
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

/// [`ViewScore`]s of `scores`, one per kind of view in order of first appearance (plain
/// means, like the whole split's).
fn by_view(scores: &[FrameScore]) -> Vec<ViewScore> {
    let mut kinds: Vec<&str> = Vec::new();
    for v in scores.iter().filter_map(|s| s.view.as_deref()) {
        if !kinds.contains(&v) {
            kinds.push(v);
        }
    }
    kinds
        .into_iter()
        .map(|kind| {
            let of: Vec<&FrameScore> = scores
                .iter()
                .filter(|s| s.view.as_deref() == Some(kind))
                .collect();
            let psnrs: Vec<f64> = of.iter().map(|s| s.psnr).collect();
            let heads: Vec<f64> = of.iter().filter_map(|s| s.head_psnr).collect();
            let mouths: Vec<f64> = of.iter().filter_map(|s| s.mouth_psnr).collect();
            ViewScore {
                view: kind.to_string(),
                frames: of.len(),
                psnr: mean(psnrs).unwrap_or(f64::NAN),
                head_psnr: mean(heads),
                mouth_psnr: mean(mouths),
            }
        })
        .collect()
}

impl Evaluation {
    /// An error naming every model that rendered NaN or infinite pixels, if any did.
    pub fn check_finite(&self) -> Result<()> {
        let broken: Vec<String> = self
            .models
            .iter()
            .filter(|r| r.non_finite_frames > 0)
            .map(|r| {
                format!(
                    "{} rendered {} of {} frames with NaN or infinite pixels",
                    r.model,
                    r.non_finite_frames,
                    r.frames.len()
                )
            })
            .collect();
        if broken.is_empty() {
            Ok(())
        } else {
            Err(Error::NonFinite(format!(
                "{}; their scores are void",
                broken.join("; ")
            )))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::pick_frames;

    /// `novel`'s pattern: turned, closer, farther, over and over.
    fn novel(len: usize) -> Vec<Option<&'static str>> {
        let kinds = [Some("turned 1.5x"), Some("closer"), Some("farther")];
        (0..len).map(|i| kinds[i % 3]).collect()
    }

    #[test]
    fn a_third_of_novel_holds_every_kind_of_view() {
        let kinds = novel(84);
        let picked = pick_frames(&kinds, 28);
        assert_eq!(picked.len(), 28);
        assert!(picked.windows(2).all(|w| w[0] < w[1]));
        for kind in ["turned 1.5x", "closer", "farther"] {
            let count = picked.iter().filter(|&&i| kinds[i] == Some(kind)).count();
            assert!((9..=10).contains(&count), "{kind}: {count} of 28");
        }
        // Each kind's frames still span the split.
        assert!(picked[0] < 3 && picked[27] >= 75, "{picked:?}");
    }

    #[test]
    fn a_split_without_views_is_spread_as_a_whole() {
        let kinds = vec![None; 30];
        assert_eq!(pick_frames(&kinds, 4), vec![0, 7, 15, 22]);
        assert_eq!(pick_frames(&kinds, 0), vec![0]);
        assert_eq!(pick_frames(&kinds, 99), (0..30).collect::<Vec<_>>());
        assert_eq!(pick_frames(&[], 4), Vec::<usize>::new());
    }

    #[test]
    fn fewer_frames_than_kinds_take_the_earliest_kinds() {
        let kinds = novel(9);
        assert_eq!(pick_frames(&kinds, 1), vec![0]);
        assert_eq!(pick_frames(&kinds, 2), vec![0, 1]);
        assert_eq!(pick_frames(&kinds, 9), (0..9).collect::<Vec<_>>());
    }
}
