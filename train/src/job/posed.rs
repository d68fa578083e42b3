//! The ablation that decides whether the teacher earns its time: the teacher, a distilled
//! student with pseudo views, one without, and a pixels-only student, every student given
//! the same total wall time (the distilled ones `minutes` after the teacher's, their
//! teacher targets included; the pixels-only one the teacher's minutes plus the longest
//! distilled student's), each scored on every evaluation
//! split the dataset has (`val`, `novel`, `voice`), with a pose-sweep strip: one row per
//! model rendering the `sweep` split (the head turning from the front out to twice the
//! recorded range) under the ground truth. Writes `RUN/posed.md`, `RUN/posed.json` and
//! `RUN/posed_sweep.png`.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use nldf_core::dataset::{AudioChoice, Split};
use nldf_core::image::{ImageRgb, grid};
use nldf_core::run_files::{has_checkpoint, teacher_dir};
use serde::Serialize;

use crate::error::{Error, Result};
use crate::job::student::{PseudoSettings, StudentJob, StudentSource};
use crate::job::{JobEvent, OnEvent};
use crate::networks::student::StudentConfig;
use crate::reports::eval::{EvalReport, FrameModel, eval_models};
use crate::trainers::data::TrainData;
use crate::trainers::student_trainer::StudentModel;
use crate::trainers::teacher_trainer::TeacherModel;

/// What `nldf ablate --posed` was asked to do.
#[derive(Debug, Clone, PartialEq)]
pub struct PosedJob {
    /// The dataset the teacher was trained on, with its evaluation splits.
    pub data: PathBuf,
    /// The run folder with a trained `RUN/teacher`; students go to `RUN/posed_<name>`.
    pub run: PathBuf,
    /// The students' shape.
    pub model: StudentConfig,
    /// Student minutes after the teacher's (the pixels-only student gets the teacher's
    /// minutes on top).
    pub minutes: f64,
    /// Pseudo views of the student that has them.
    pub pseudo_frames: usize,
    /// Their pose range, a factor of the recorded range.
    pub pose_range: f32,
    /// Hit pixels the teacher renders per pseudo view (0: all).
    pub pseudo_rays: usize,
    /// At most this many frames per split are scored.
    pub frames: Option<usize>,
}

/// One model's scores on one split.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PosedScore {
    pub split: String,
    pub psnr: f64,
    pub ssim: f64,
    pub head_psnr: Option<f64>,
    pub mouth_psnr: Option<f64>,
}

/// One row of the posed ablation.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PosedRow {
    /// What the model is.
    pub variant: String,
    /// Its folder.
    pub folder: PathBuf,
    /// Training steps.
    pub steps: usize,
    /// Its own training minutes (teacher targets included for a distilled student).
    pub own_minutes: f64,
    /// Total minutes behind it: the teacher's plus its own for a distilled student.
    pub total_minutes: f64,
    pub scores: Vec<PosedScore>,
}

/// What the posed ablation wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct PosedReport {
    pub rows: Vec<PosedRow>,
    /// The Markdown table (also in `posed.md`).
    pub markdown: String,
    pub files: Vec<PathBuf>,
}

/// The splits scored, in table order.
const SPLITS: [Split; 3] = [Split::Val, Split::Novel, Split::Voice];

impl PosedJob {
    /// Trains (or reuses) the three students, then scores the teacher and each.
    pub fn run(&self, stop: &AtomicBool, on_event: OnEvent) -> Result<PosedReport> {
        if !(self.minutes.is_finite() && self.minutes > 0.0) {
            return Err(Error::Config(format!(
                "the posed ablation needs a positive student budget in minutes, got {}",
                self.minutes
            )));
        }
        let dir = teacher_dir(&self.run);
        let teacher = TeacherModel::open(&dir)
            .map_err(|e| e.context(format!("loading the teacher from {}", dir.display())))?;
        let teacher_minutes = teacher.trained_s / 60.0;
        let audio = AudioChoice::Matching(teacher.cfg.model.audio.features.clone());
        // Every split is loaded before hours of training start, and scored from here.
        let held_out = SPLITS
            .into_iter()
            .chain([Split::Sweep])
            .map(|split| TrainData::open_held_out(&self.data, false, &audio, split))
            .collect::<Result<Vec<_>>>()?;
        let students = self.train_students(teacher_minutes, stop, on_event)?;
        let mut models: Vec<&dyn FrameModel> = vec![&teacher];
        models.extend(students.iter().map(|(_, s, _)| s as &dyn FrameModel));
        let reports = self.score_splits(&models, &held_out, on_event)?;
        let strip = self.run.join("posed_sweep.png");
        sweep_strip(&models, &held_out[SPLITS.len()], &strip)?;
        let mut rows = vec![PosedRow {
            variant: teacher.describe(),
            folder: dir.clone(),
            steps: teacher.step,
            own_minutes: teacher_minutes,
            total_minutes: teacher_minutes,
            scores: scores_of(&reports[0]),
        }];
        for (k, (label, run, distilled)) in students.iter().enumerate() {
            let own = run.trained_s / 60.0;
            rows.push(PosedRow {
                variant: format!(
                    "{} ({}x{})",
                    label, run.cfg.model.depth, run.cfg.model.width
                ),
                folder: run.dir.clone(),
                steps: run.step,
                own_minutes: own,
                total_minutes: own + if *distilled { teacher_minutes } else { 0.0 },
                scores: scores_of(&reports[k + 1]),
            });
        }
        write_reports(&self.run, rows, strip)
    }

    /// The three students' jobs, each with its label and whether it is distilled.
    fn variants(&self) -> [(String, StudentJob, bool); 3] {
        let student = |name: &str, distill: bool, pseudo: usize, minutes: f64| StudentJob {
            data: self.data.clone(),
            run: self.run.clone(),
            name: format!("posed_{name}"),
            source: StudentSource::Settings {
                model: Box::new(self.model.clone()),
                distill,
                pool: true,
                pseudo: PseudoSettings {
                    frames: Some(pseudo),
                    pose_range: Some(self.pose_range),
                    rays: Some(self.pseudo_rays),
                },
            },
            iters: Some(1_000_000),
            minutes: Some(minutes),
            resume: false,
        };
        // The pixels-only student's budget is set once the distilled ones have trained:
        // the teacher's minutes plus the longest distilled student's own.
        [
            (
                "student, distilled, with pseudo views".to_string(),
                student("pseudo", true, self.pseudo_frames, self.minutes),
                true,
            ),
            (
                "student, distilled, recorded frames only".to_string(),
                student("distilled", true, 0, self.minutes),
                true,
            ),
            (
                "student, pixels only".to_string(),
                student("pixels", false, 0, 0.0),
                false,
            ),
        ]
    }

    /// Trains (or resumes) each student in turn and opens it: its label, model and whether
    /// it is distilled.
    fn train_students(
        &self,
        teacher_minutes: f64,
        stop: &AtomicBool,
        on_event: OnEvent,
    ) -> Result<Vec<(String, StudentModel, bool)>> {
        let mut students: Vec<(String, StudentModel, bool)> = Vec::new();
        for (label, job, distilled) in &self.variants() {
            let dir = job.dir();
            let minutes = if *distilled {
                job.minutes
            } else {
                let longest = students
                    .iter()
                    .map(|(_, s, _)| s.trained_s / 60.0)
                    .fold(self.minutes, f64::max);
                Some(teacher_minutes + longest)
            };
            let job = StudentJob {
                resume: has_checkpoint(&dir),
                minutes,
                ..job.clone()
            };
            on_event(&JobEvent::Stage(format!("{label} -> {}", dir.display())));
            job.plan(on_event)?.run(stop, on_event)?;
            if stop.load(Ordering::Relaxed) {
                return Err(Error::Config(
                    "stopped; run the same command again to resume".into(),
                ));
            }
            let run = StudentModel::open(&dir)?;
            let label = trained_label(label, &run);
            students.push((label, run, *distilled));
        }
        Ok(students)
    }

    /// Scores `models` on each split of [`SPLITS`] (`held_out`, in that order); per model,
    /// its reports in split order.
    fn score_splits(
        &self,
        models: &[&dyn FrameModel],
        held_out: &[TrainData],
        on_event: OnEvent,
    ) -> Result<Vec<Vec<EvalReport>>> {
        let mut reports: Vec<Vec<EvalReport>> = vec![Vec::new(); models.len()];
        for (split, data) in SPLITS.into_iter().zip(held_out) {
            on_event(&JobEvent::Stage(format!(
                "scoring the {} split",
                split.name()
            )));
            let out = self.run.join("eval_posed").join(split.name());
            let total = self
                .frames
                .unwrap_or(usize::MAX)
                .min(data.dataset.val.len());
            let mut done = 0;
            let evaluation = eval_models(models, data, split, self.frames, &out, &mut || {
                done += 1;
                on_event(&JobEvent::Progress {
                    what: format!("{} frames", split.name()),
                    done,
                    total,
                })
            })?;
            evaluation.check_finite()?;
            for (k, r) in evaluation.models.into_iter().enumerate() {
                reports[k].push(r);
            }
        }
        Ok(reports)
    }
}

/// A student's row label, from what its run was trained with (a reused run keeps its
/// own): `label` unless it has pseudo views.
fn trained_label(label: &str, run: &StudentModel) -> String {
    let t = &run.cfg.train;
    if t.pseudo_frames == 0 {
        label.to_string()
    } else {
        let pixels = match t.pseudo_rays {
            0 => String::new(),
            n => format!(" of {n} pixels"),
        };
        format!(
            "student, distilled, {} pseudo views{pixels} at {}x the recorded poses",
            t.pseudo_frames, t.pose_range
        )
    }
}

fn scores_of(reports: &[EvalReport]) -> Vec<PosedScore> {
    reports
        .iter()
        .map(|r| PosedScore {
            split: r.split.clone(),
            psnr: r.psnr,
            ssim: r.ssim,
            head_psnr: r.head_psnr,
            mouth_psnr: r.mouth_psnr,
        })
        .collect()
}

/// The pose-sweep strip: the ground truth of every `sweep` frame in the first row, then
/// one row per model.
pub fn sweep_strip(models: &[&dyn FrameModel], data: &TrainData, path: &Path) -> Result<()> {
    let frames = data.dataset.frames(Split::Sweep);
    let mut rows: Vec<Vec<ImageRgb>> = vec![Vec::new(); models.len() + 1];
    for frame in frames {
        rows[0].push(data.dataset.load_image(frame)?);
        for (k, m) in models.iter().enumerate() {
            rows[k + 1].push(m.render_frame(data, frame)?);
        }
    }
    grid(&rows, 2, [1.0; 3]).save_png(path)?;
    Ok(())
}

fn write_reports(run: &Path, rows: Vec<PosedRow>, strip: PathBuf) -> Result<PosedReport> {
    let opt = |v: Option<f64>| v.map(|m| format!("{m:.2}")).unwrap_or_else(|| "-".into());
    let mut md = String::from(
        "| model | steps | own min | total min | val PSNR | val mouth | novel PSNR | novel mouth | voice PSNR | voice mouth | val SSIM | novel SSIM |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in &rows {
        let get = |split: &str| r.scores.iter().find(|s| s.split == split);
        let psnr = |split: &str| get(split).map_or("-".into(), |s| format!("{:.2}", s.psnr));
        let mouth = |split: &str| get(split).map_or("-".into(), |s| opt(s.mouth_psnr));
        let ssim = |split: &str| get(split).map_or("-".into(), |s| format!("{:.4}", s.ssim));
        md.push_str(&format!(
            "| {} | {} | {:.1} | {:.1} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
            r.variant,
            r.steps,
            r.own_minutes,
            r.total_minutes,
            psnr("val"),
            mouth("val"),
            psnr("novel"),
            mouth("novel"),
            psnr("voice"),
            mouth("voice"),
            ssim("val"),
            ssim("novel"),
        ));
    }
    let md_path = run.join("posed.md");
    nldf_core::files::write_atomic(&md_path, md.as_bytes())?;
    let json = run.join("posed.json");
    nldf_core::files::write_json(&json, &rows)?;
    Ok(PosedReport {
        rows,
        markdown: md,
        files: vec![md_path, json, strip],
    })
}
