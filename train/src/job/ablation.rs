//! The paper's ablations on one dataset and teacher (Tables 1-3): distilled against
//! pixels-only students, with and without the beam pool at equal iterations, several
//! depths, plus a pixels-only student given the same total wall time as the teacher and the
//! distilled student together. Each variant is a student folder `RUN/ablate_<name>`;
//! finished ones are reused, interrupted ones resume. Writes `RUN/ablation.md`,
//! `RUN/ablation.json` and `RUN/ablation.png` (validation PSNR against wall time).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use nldf_core::dataset::{AudioChoice, Split};
use nldf_core::run_files::{LOG_FILE, TARGETS_FILE, has_checkpoint, teacher_dir};
use serde::Serialize;

use crate::error::{Error, Result};
use crate::job::student::{PseudoSettings, StudentJob, StudentSource};
use crate::job::{JobEvent, OnEvent};
use crate::networks::student::StudentConfig;
use crate::reports::eval::FrameModel;
use crate::trainers::data::TrainData;
use crate::trainers::student_trainer::StudentModel;
use crate::trainers::teacher_trainer::TeacherModel;

/// What `nldf ablate` was asked to do.
#[derive(Debug, Clone, PartialEq)]
pub struct AblationJob {
    /// The dataset the teacher was trained on.
    pub data: PathBuf,
    /// The run folder with a trained `RUN/teacher`; variants go beside it.
    pub run: PathBuf,
    /// Training steps of every fixed-iteration variant.
    pub iters: usize,
    /// The shape of the distillation and pool comparisons (Tables 1 and 2), with its name
    /// in folder names (`28`, `tiny`).
    pub model: (String, StudentConfig),
    /// The other shapes of Table 3, named likewise.
    pub depths: Vec<(String, StudentConfig)>,
    /// Also train the pixels-only student given the teacher's and the distilled student's
    /// wall time (Table 4).
    pub wall_time: bool,
}

/// One row of the ablation.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AblationRow {
    /// The paper's table the row belongs to (`1: distillation`, ...).
    pub table: String,
    /// What the variant is.
    pub variant: String,
    /// Its student folder.
    pub folder: PathBuf,
    /// Training steps done.
    pub steps: usize,
    /// Training minutes (its teacher targets included).
    pub minutes: f64,
    /// Scores over every validation frame.
    pub psnr: f64,
    pub ssim: f64,
    pub head_psnr: Option<f64>,
    pub mouth_psnr: Option<f64>,
}

/// What the ablation wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct AblationReport {
    /// One row per variant, in training order.
    pub rows: Vec<AblationRow>,
    /// The Markdown table (also in `ablation.md`).
    pub markdown: String,
    /// `ablation.md`, `ablation.json` and `ablation.png`.
    pub files: Vec<PathBuf>,
}

/// One fixed-iteration variant: table, label, and the student job (named for its folder).
type Variant = (String, String, StudentJob);

/// A checked ablation: the teacher and the data are loaded, the variants listed.
pub struct AblationPlan {
    job: AblationJob,
    teacher: TeacherModel,
    /// The teacher's training minutes, as its checkpoint records them.
    teacher_minutes: f64,
    data: TrainData,
    variants: Vec<Variant>,
    /// The pixels-only student of Table 4, whose budget is set once the distilled variant
    /// has trained; `None` without it.
    wall_time: Option<StudentJob>,
}

impl AblationJob {
    /// Opens the teacher and the data and lists the variants; nothing is trained yet.
    pub fn plan(&self) -> Result<AblationPlan> {
        if self.iters == 0 {
            return Err(Error::Config(
                "the ablation needs at least 1 training step per variant".into(),
            ));
        }
        let dir = teacher_dir(&self.run);
        let teacher = TeacherModel::open(&dir)
            .map_err(|e| e.context(format!("loading the teacher from {}", dir.display())))?;
        let teacher_minutes = teacher.trained_s / 60.0;
        let audio = AudioChoice::Matching(teacher.cfg.model.audio.features.clone());
        let data = TrainData::open_with(&self.data, false, &audio)?;
        let base = |name: String, model: &StudentConfig, distill: bool, pool: bool| StudentJob {
            data: self.data.clone(),
            run: self.run.clone(),
            name,
            source: StudentSource::Settings {
                model: Box::new(model.clone()),
                distill,
                pool,
                pseudo: PseudoSettings::default(),
            },
            iters: Some(self.iters),
            minutes: None,
            resume: false,
        };
        let (d, model) = &self.model;
        let mut variants: Vec<Variant> = vec![
            (
                "1: distillation".into(),
                format!("depth {d}, distilled"),
                base(format!("ablate_d{d}"), model, true, true),
            ),
            (
                "1: distillation".into(),
                format!("depth {d}, pixels only"),
                base(format!("ablate_d{d}_pixels"), model, false, true),
            ),
            (
                "2: beam pool".into(),
                format!("depth {d}, distilled, no pool"),
                base(format!("ablate_d{d}_nopool"), model, true, false),
            ),
        ];
        for (dn, shape) in self.depths.iter().filter(|(dn, _)| dn != d) {
            variants.push((
                "3: depth".into(),
                format!("depth {dn}, distilled"),
                base(format!("ablate_d{dn}"), shape, true, true),
            ));
        }
        let wall_time = self.wall_time.then(|| StudentJob {
            iters: Some(1_000_000),
            ..base(format!("ablate_d{d}_pixels_walltime"), model, false, true)
        });
        Ok(AblationPlan {
            job: self.clone(),
            teacher,
            teacher_minutes,
            data,
            variants,
            wall_time,
        })
    }
}

impl AblationPlan {
    /// Trains (or reuses) every variant, scores each on the whole validation split and
    /// writes the reports.
    pub fn run(self, stop: &AtomicBool, on_event: OnEvent) -> Result<AblationReport> {
        let teacher_minutes = self.teacher_minutes;
        let n_val = self.data.dataset.frames(Split::Val).len().max(1);
        let mut rows = Vec::new();
        let mut train = |table: &str, label: &str, job: StudentJob| -> Result<AblationRow> {
            let dir = job.dir();
            // A finished variant resumes with nothing left to do.
            let job = StudentJob {
                resume: has_checkpoint(&dir),
                ..job
            };
            on_event(&JobEvent::Stage(format!(
                "{table}: {label} -> {}",
                dir.display()
            )));
            if matches!(job.source, StudentSource::Settings { distill: true, .. }) {
                share_targets(&self.job.run, &dir)?;
            }
            job.plan(on_event)?.run(stop, on_event)?;
            let run = StudentModel::open(&dir)?;
            let s = run.validation_scores(&self.data, n_val)?;
            Ok(AblationRow {
                table: table.into(),
                variant: label.into(),
                folder: dir,
                steps: run.step,
                minutes: run.trained_s / 60.0,
                psnr: s.psnr,
                ssim: s.ssim,
                head_psnr: s.head_psnr,
                mouth_psnr: s.mouth_psnr,
            })
        };
        for (table, label, job) in &self.variants {
            rows.push(train(table, label, job.clone())?);
            if stop.load(Ordering::Relaxed) {
                // Interrupted: report the variants trained so far; a new run resumes.
                return write_reports(&self.job.run, &self.teacher, teacher_minutes, rows);
            }
        }
        if let Some(pixels) = self.wall_time.clone() {
            let d = &self.job.model.0;
            // Teacher time plus the distilled student's (its targets included).
            let distilled = rows.first().map(|r: &AblationRow| r.minutes).unwrap_or(0.0);
            let budget = teacher_minutes + distilled;
            rows.push(train(
                "4: equal wall time",
                &format!("depth {d}, pixels only, {budget:.1} min (teacher + distilled student)"),
                StudentJob {
                    minutes: Some(budget),
                    ..pixels
                },
            )?);
            rows.push(AblationRow {
                table: "4: equal wall time".into(),
                variant: format!(
                    "depth {d}, distilled: teacher {teacher_minutes:.1} min + student {distilled:.1} min"
                ),
                minutes: budget,
                ..rows[0].clone()
            });
        }
        write_reports(&self.job.run, &self.teacher, teacher_minutes, rows)
    }
}

fn write_reports(
    run: &Path,
    teacher: &TeacherModel,
    teacher_minutes: f64,
    rows: Vec<AblationRow>,
) -> Result<AblationReport> {
    let opt = |v: Option<f64>| v.map(|m| format!("{m:.2}")).unwrap_or_else(|| "-".into());
    let mut md = format!(
        "# Ablation on {}\n\nTeacher: {} at step {}, {:.1} min. Scores over every validation frame.\n\n\
         | table | variant | steps | minutes | PSNR (dB) | SSIM | head PSNR (dB) | mouth PSNR (dB) |\n|---|---|---|---|---|---|---|---|\n",
        run.display(),
        teacher.describe(),
        teacher.step,
        teacher_minutes
    );
    for r in &rows {
        md.push_str(&format!(
            "| {} | {} | {} | {:.1} | {:.2} | {:.4} | {} | {} |\n",
            r.table,
            r.variant,
            r.steps,
            r.minutes,
            r.psnr,
            r.ssim,
            opt(r.head_psnr),
            opt(r.mouth_psnr)
        ));
    }
    let mut series = Vec::new();
    let mut seen = std::collections::HashSet::new();
    for r in rows.iter().filter(|r| seen.insert(r.folder.clone())) {
        let log = crate::trainers::log::read_log(&r.folder.join(LOG_FILE))?;
        series.push(crate::trainers::plot::Series {
            label: r.variant.clone(),
            color: crate::trainers::plot::palette(series.len()),
            points: log
                .iter()
                .filter_map(|l| l.val_psnr.map(|v| (l.elapsed_s / 60.0, v)))
                .collect(),
            marked: true,
        });
    }
    let png = run.join("ablation.png");
    crate::trainers::plot::plot_lines(&png, "student validation PSNR against wall time", &series)?;
    let md_path = run.join("ablation.md");
    nldf_core::files::write_atomic(&md_path, md.as_bytes())?;
    let json = run.join("ablation.json");
    nldf_core::files::write_json(&json, &rows)?;
    Ok(AblationReport {
        rows,
        markdown: md,
        files: vec![md_path, json, png],
    })
}

/// Copies the teacher's cached segment colours of an earlier variant into `dir` when `dir`
/// has none: variants with the same views reuse them instead of rendering the teacher
/// again (the trainer checks that the cache fits its views and teacher, and renders anew
/// when it does not).
fn share_targets(run: &Path, dir: &Path) -> Result<()> {
    if dir.join(TARGETS_FILE).is_file() {
        return Ok(());
    }
    let Ok(entries) = std::fs::read_dir(run) else {
        return Ok(());
    };
    let mut caches: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path().join(TARGETS_FILE)))
        .filter(|p| p.is_file())
        .collect();
    caches.sort();
    // The newest: the one rendered for this ablation's first distilled variant.
    let Some(source) = caches
        .into_iter()
        .max_by_key(|p| p.metadata().and_then(|m| m.modified()).ok())
    else {
        return Ok(());
    };
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let dest = dir.join(TARGETS_FILE);
    std::fs::copy(&source, &dest)
        .map_err(|e| Error::io(&dest, e).context(format!("copying {}", source.display())))?;
    Ok(())
}
