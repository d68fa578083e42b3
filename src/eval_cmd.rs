//! `nldf eval`: renders held-out frames with a trained model and reports PSNR, SSIM and
//! mouth-region PSNR as a table and as JSON, with the renders and a comparison grid.

use std::path::PathBuf;

use anyhow::{Context, Result};
use nldf_core::dataset::Split;
use nldf_train::data::TrainData;
use nldf_train::eval::eval_models;
use nldf_train::teacher_trainer::TeacherRun;

use crate::progress::progress_bar;

/// Dataset splits.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum SplitArg {
    Train,
    Val,
}

#[derive(clap::Args, Debug)]
pub struct EvalArgs {
    /// Run folder (with a trained RUN/teacher).
    #[arg(long)]
    pub run: PathBuf,
    /// Dataset folder the run was trained on.
    #[arg(long)]
    pub data: PathBuf,
    /// Which split to render.
    #[arg(long, value_enum, default_value_t = SplitArg::Val)]
    pub split: SplitArg,
    /// Render at most this many frames, spread evenly over the split.
    #[arg(long)]
    pub frames: Option<usize>,
    /// Output folder (default RUN/eval/<split>).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Runs `nldf eval`.
pub fn run(args: EvalArgs) -> Result<()> {
    use nldf_train::eval::FrameModel;
    use nldf_train::student_trainer::StudentRun;
    let split = match args.split {
        SplitArg::Train => Split::Train,
        SplitArg::Val => Split::Val,
    };
    let name = format!("{split:?}").to_lowercase();
    let out = args
        .out
        .unwrap_or_else(|| args.run.join("eval").join(&name));
    let teacher_dir = args.run.join("teacher");
    let teacher = TeacherRun::open(&teacher_dir, false)
        .with_context(|| format!("loading the teacher from {}", teacher_dir.display()))?;
    // Every student folder of the run (RUN/student, and ablation variants beside it).
    let mut students = Vec::new();
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(&args.run)
        .with_context(|| format!("reading {}", args.run.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.join("render.json").is_file() && p.join(nldf_core::run_files::MODEL_FILE).is_file()
        })
        .collect();
    dirs.sort();
    for dir in dirs {
        students.push(
            StudentRun::open(&dir, false)
                .with_context(|| format!("loading the student from {}", dir.display()))?,
        );
    }
    let audio = nldf_core::dataset::AudioChoice::Matching(teacher.cfg.model.audio.features.clone());
    let data = TrainData::open_with(&args.data, false, &audio)?;
    crate::train_cmd::say_audio(&data);
    let n = args
        .frames
        .unwrap_or(usize::MAX)
        .min(data.dataset.frames(split).len());
    let mut models: Vec<&dyn FrameModel> = vec![&teacher];
    models.extend(students.iter().map(|s| s as &dyn FrameModel));
    let bar = progress_bar(n as u64, "rendering");
    let evaluation = eval_models(&models, &data, split, args.frames, &out, &mut || bar.inc(1))?;
    bar.finish_and_clear();
    let opt = |v: Option<f64>| v.map(|m| format!("{m:.2}")).unwrap_or_else(|| "-".into());
    println!(
        "| model | split | step | frames | PSNR (dB) | SSIM | face PSNR (dB) | mouth PSNR (dB) | GMAC / frame | s / frame |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for r in &evaluation.models {
        println!(
            "| {} | {} | {} | {} | {:.2} | {:.4} | {} | {} | {:.2} | {:.2} |",
            r.model,
            r.split,
            r.step,
            r.frames.len(),
            r.psnr,
            r.ssim,
            opt(r.face_psnr),
            opt(r.mouth_psnr),
            r.macs_per_frame / 1e9,
            r.render_s_per_frame
        );
    }
    let rows: Vec<serde_json::Value> = evaluation
        .models
        .iter()
        .map(|r| {
            serde_json::json!({
                "model": r.model, "split": r.split, "step": r.step,
                "psnr": r.psnr, "ssim": r.ssim, "face_psnr": r.face_psnr,
                "mouth_psnr": r.mouth_psnr, "macs_per_frame": r.macs_per_frame,
                "frames": r.frames.len(), "non_finite_frames": r.non_finite_frames,
            })
        })
        .collect();
    println!("{}", serde_json::to_string(&rows)?);
    println!("wrote to {}:", out.display());
    for m in &models {
        println!("  {}/ ({} PNG)", out.join(m.label()).display(), n);
    }
    for f in evaluation
        .files
        .iter()
        .filter(|f| f.extension().is_some_and(|e| e == "json") || f.ends_with("grid.png"))
    {
        println!("  {}", f.display());
    }
    let broken: Vec<String> = evaluation
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
    if !broken.is_empty() {
        anyhow::bail!("{}; their scores are void", broken.join("; "));
    }
    Ok(())
}
