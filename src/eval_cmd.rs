//! `nldf eval`: renders held-out frames with a trained model and reports PSNR, SSIM and
//! mouth-region PSNR as a table and as JSON, with the renders and a comparison grid.

use std::path::PathBuf;

use anyhow::{Context, Result};
use nldf_core::dataset::Split;
use nldf_train::eval::eval_teacher;
use nldf_train::trainer::{TeacherRun, TrainData};

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
    let data = TrainData::open(&args.data, false)?;
    let n = args
        .frames
        .unwrap_or(usize::MAX)
        .min(data.dataset.frames(split).len());
    let bar = progress_bar(n as u64, "rendering");
    let report = eval_teacher(&teacher, &data, split, args.frames, &out, &mut || {
        bar.inc(1)
    })?;
    bar.finish_and_clear();
    let opt = |v: Option<f64>| v.map(|m| format!("{m:.2}")).unwrap_or_else(|| "-".into());
    println!(
        "| model | split | step | frames | PSNR (dB) | SSIM | face PSNR (dB) | mouth PSNR (dB) | s / frame |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    println!(
        "| {} | {} | {} | {} | {:.2} | {:.4} | {} | {} | {:.2} |",
        report.model,
        report.split,
        report.step,
        report.frames.len(),
        report.psnr,
        report.ssim,
        opt(report.face_psnr),
        opt(report.mouth_psnr),
        report.render_s_per_frame
    );
    println!(
        "{}",
        serde_json::to_string(&serde_json::json!({
            "model": report.model, "split": report.split, "step": report.step,
            "psnr": report.psnr, "ssim": report.ssim, "face_psnr": report.face_psnr,
            "mouth_psnr": report.mouth_psnr,
            "frames": report.frames.len(),
        }))?
    );
    println!("wrote to {}:", out.display());
    println!(
        "  {}/ ({} PNG)",
        out.join("teacher").display(),
        report.frames.len()
    );
    for f in report
        .files
        .iter()
        .filter(|f| !f.starts_with(out.join("teacher")))
    {
        println!("  {}", f.display());
    }
    Ok(())
}
