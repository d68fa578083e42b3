//! `nldf ablate`: the paper's Tables 1-3 on one dataset (with and without distillation;
//! with and without the beam pool at equal iterations; depth 28 / 50 / 88), plus a
//! pixels-only student given the same total wall time as the teacher and the distilled
//! student together. Each variant is a student folder `RUN/ablate_<name>`; finished ones
//! are reused, interrupted ones resume. Writes `RUN/ablation.md`, `RUN/ablation.json` and
//! `RUN/ablation.png` (validation PSNR against wall time, every variant).

use std::path::PathBuf;

use anyhow::{Context, Result};
use nldf_core::dataset::Split;
use nldf_train::data::TrainData;
use nldf_train::student_trainer::StudentRun;
use nldf_train::teacher_trainer::TeacherRun;
use serde::Serialize;

use crate::train_cmd::{StudentArgs, StudentDepth, run_student};

#[derive(clap::Args, Debug)]
pub struct AblateArgs {
    /// Dataset folder the teacher was trained on.
    #[arg(long)]
    pub data: PathBuf,
    /// Run folder with a trained RUN/teacher; variants go to RUN/ablate_<name>.
    #[arg(long)]
    pub run: PathBuf,
    /// Training steps of every fixed-iteration variant.
    #[arg(long, default_value_t = 1000)]
    pub iters: usize,
    /// Depth of the distillation and pool comparisons (Tables 1 and 2).
    #[arg(long, value_enum, default_value_t = StudentDepth::D88)]
    pub depth: StudentDepth,
    /// Hidden width of every variant (the paper: 256).
    #[arg(long)]
    pub width: Option<usize>,
    /// Depths of Table 3.
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = [StudentDepth::D28, StudentDepth::D50, StudentDepth::D88])]
    pub depths: Vec<StudentDepth>,
    /// Skip the wall-time-matched pixels-only student.
    #[arg(long)]
    pub no_wall_time: bool,
}

/// One row of the ablation.
#[derive(Debug, Clone, Serialize)]
struct Row {
    table: String,
    variant: String,
    folder: PathBuf,
    steps: usize,
    minutes: f64,
    psnr: f64,
    ssim: f64,
    face_psnr: Option<f64>,
    mouth_psnr: Option<f64>,
}

/// Runs `nldf ablate`.
pub fn run(args: AblateArgs) -> Result<()> {
    let teacher_dir = args.run.join("teacher");
    let teacher = TeacherRun::open(&teacher_dir, false)
        .with_context(|| format!("loading the teacher from {}", teacher_dir.display()))?;
    let teacher_minutes = teacher.elapsed() / 60.0;
    let audio = nldf_core::dataset::AudioChoice::Matching(teacher.cfg.model.audio.features.clone());
    let data = TrainData::open_with(&args.data, false, &audio)?;
    let n_val = data.dataset.frames(Split::Val).len().max(1);
    let base = StudentArgs {
        data: args.data.clone(),
        run: args.run.clone(),
        depth: args.depth,
        width: args.width,
        no_distill: false,
        no_pool: false,
        pseudo_frames: None,
        config: None,
        iters: Some(args.iters),
        minutes: None,
        name: String::new(),
        resume: false,
    };
    let depth_name = |d: StudentDepth| match d {
        StudentDepth::D28 => "28".to_string(),
        StudentDepth::D50 => "50".to_string(),
        StudentDepth::D88 => "88".to_string(),
        StudentDepth::Tiny => "tiny".to_string(),
    };
    let d = depth_name(args.depth);
    // (table, variant label, folder name, arguments)
    let mut plan: Vec<(String, String, String, StudentArgs)> = vec![
        (
            "1: distillation".into(),
            format!("depth {d}, distilled"),
            format!("ablate_d{d}"),
            base.clone(),
        ),
        (
            "1: distillation".into(),
            format!("depth {d}, pixels only"),
            format!("ablate_d{d}_pixels"),
            StudentArgs {
                no_distill: true,
                ..base.clone()
            },
        ),
        (
            "2: beam pool".into(),
            format!("depth {d}, distilled, no pool"),
            format!("ablate_d{d}_nopool"),
            StudentArgs {
                no_pool: true,
                ..base.clone()
            },
        ),
    ];
    for &depth in &args.depths {
        if depth != args.depth {
            let dn = depth_name(depth);
            plan.push((
                "3: depth".into(),
                format!("depth {dn}, distilled"),
                format!("ablate_d{dn}"),
                StudentArgs {
                    depth,
                    ..base.clone()
                },
            ));
        }
    }
    let mut rows = Vec::new();
    let train = |table: &str, label: &str, name: &str, args: StudentArgs| -> Result<Row> {
        let dir = args.run.join(name);
        let done = dir.join(nldf_core::run_files::MODEL_FILE).is_file();
        // A finished variant resumes with nothing left to do.
        let args = StudentArgs {
            name: name.to_string(),
            resume: done,
            ..args
        };
        println!("== {table}: {label} -> {}", dir.display());
        if !args.no_distill {
            share_targets(&args.run, &dir)?;
        }
        run_student(args)?;
        let run = StudentRun::open(&dir, false)?;
        let minutes = run.elapsed() / 60.0;
        let s = run.validation_scores(&data, n_val)?;
        Ok(Row {
            table: table.into(),
            variant: label.into(),
            folder: dir,
            steps: run.step,
            minutes,
            psnr: s.psnr,
            ssim: s.ssim,
            face_psnr: s.face_psnr,
            mouth_psnr: s.mouth_psnr,
        })
    };
    for (table, label, name, a) in plan {
        rows.push(train(&table, &label, &name, a)?);
    }
    if !args.no_wall_time {
        // Teacher time plus the distilled student's (its targets included).
        let distilled = rows
            .first()
            .map(|r| r.minutes)
            .context("the distilled variant did not run")?;
        let budget = teacher_minutes + distilled;
        rows.push(train(
            "4: equal wall time",
            &format!("depth {d}, pixels only, {budget:.1} min (teacher + distilled student)"),
            &format!("ablate_d{d}_pixels_walltime"),
            StudentArgs {
                no_distill: true,
                iters: Some(1_000_000),
                minutes: Some(budget),
                ..base.clone()
            },
        )?);
        rows.push(Row {
            table: "4: equal wall time".into(),
            variant: format!(
                "depth {d}, distilled: teacher {teacher_minutes:.1} min + student {distilled:.1} min"
            ),
            minutes: budget,
            ..rows[0].clone()
        });
    }
    write_reports(&args.run, &teacher, teacher_minutes, &rows)
}

fn write_reports(
    run: &std::path::Path,
    teacher: &TeacherRun,
    teacher_minutes: f64,
    rows: &[Row],
) -> Result<()> {
    let opt = |v: Option<f64>| v.map(|m| format!("{m:.2}")).unwrap_or_else(|| "-".into());
    let mut md = format!(
        "# Ablation on {}\n\nTeacher: {} at step {}, {:.1} min. Scores over every validation frame.\n\n\
         | table | variant | steps | minutes | PSNR (dB) | SSIM | head PSNR (dB) | mouth PSNR (dB) |\n|---|---|---|---|---|---|---|---|\n",
        run.display(),
        nldf_train::eval::FrameModel::describe(teacher),
        teacher.step,
        teacher_minutes
    );
    for r in rows {
        md.push_str(&format!(
            "| {} | {} | {} | {:.1} | {:.2} | {:.4} | {} | {} |\n",
            r.table,
            r.variant,
            r.steps,
            r.minutes,
            r.psnr,
            r.ssim,
            opt(r.face_psnr),
            opt(r.mouth_psnr)
        ));
    }
    let mut series = Vec::new();
    let mut seen = std::collections::HashSet::new();
    for r in rows.iter().filter(|r| seen.insert(r.folder.clone())) {
        let log = nldf_train::log::read_log(&r.folder.join(nldf_core::run_files::LOG_FILE))?;
        series.push(nldf_train::plot::Series {
            label: r.variant.clone(),
            color: nldf_train::plot::palette(series.len()),
            points: log
                .iter()
                .filter_map(|l| l.val_psnr.map(|v| (l.elapsed_s / 60.0, v)))
                .collect(),
            marked: true,
        });
    }
    let png = run.join("ablation.png");
    nldf_train::plot::plot_lines(&png, "student validation PSNR against wall time", &series)?;
    let md_path = run.join("ablation.md");
    nldf_core::files::write_atomic(&md_path, md.as_bytes())?;
    let json = run.join("ablation.json");
    nldf_core::files::write_json(&json, &rows)?;
    print!("{md}");
    println!(
        "wrote {}, {} and {}",
        md_path.display(),
        json.display(),
        png.display()
    );
    Ok(())
}

/// Copies the teacher's cached segment colours of an earlier variant into `dir` when `dir`
/// has none: variants with the same views reuse them instead of rendering the teacher
/// again (the trainer checks that the cache fits its views and teacher, and renders anew
/// when it does not).
fn share_targets(run: &std::path::Path, dir: &std::path::Path) -> Result<()> {
    use nldf_core::run_files::TARGETS_FILE;
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
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    std::fs::copy(&source, dir.join(TARGETS_FILE))
        .with_context(|| format!("copying {} into {}", source.display(), dir.display()))?;
    Ok(())
}
