//! `nldf eval`: renders held-out frames with a trained model and reports PSNR, SSIM and
//! mouth-region PSNR as a table and as JSON (on a synthetic scene's `novel` and `sweep`
//! splits also per kind of view: turned, closer, farther; each turn), with the renders and
//! a comparison grid.

use std::path::{Path, PathBuf};

use anyhow::Result;
use nldf_core::dataset::Split;
use nldf_train::job::JobEvent;
use nldf_train::job::eval::EvalJob;
use nldf_train::reports::eval::Evaluation;

use crate::progress::EventPrinter;

/// Dataset splits: AD-NeRF's two, and the evaluation splits `nldf synth` writes (the head
/// turned beyond the recorded range and seen closer and farther; another voice; a pose
/// sweep out to twice the recorded range).
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum SplitArg {
    Train,
    Val,
    Novel,
    Voice,
    Sweep,
}

impl From<SplitArg> for Split {
    fn from(s: SplitArg) -> Split {
        match s {
            SplitArg::Train => Split::Train,
            SplitArg::Val => Split::Val,
            SplitArg::Novel => Split::Novel,
            SplitArg::Voice => Split::Voice,
            SplitArg::Sweep => Split::Sweep,
        }
    }
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
    /// Render at most this many frames, spread evenly over each kind of view the split holds
    /// (`novel`: turned, closer and farther in turn).
    #[arg(long)]
    pub frames: Option<usize>,
    /// Output folder (default RUN/eval/<split>).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Score against this dataset's frames instead of DATA's own: each frame's image and
    /// head, mouth and background regions from AGAINST's frame of the same `img_id` in the
    /// split, the models still rendering DATA's cameras. Two runs of one scene on different
    /// datasets (a dataset `nldf prepare` made from a video, and the scene the video shows)
    /// are then scored on the same pixels.
    #[arg(long)]
    pub against: Option<PathBuf>,
}

/// Runs `nldf eval`.
pub fn run(args: EvalArgs) -> Result<()> {
    let job = EvalJob {
        run: args.run,
        data: args.data,
        split: args.split.into(),
        frames: args.frames,
        out: args.out,
        against: args.against,
    };
    let mut printer = EventPrinter::default();
    let mut show = |e: &JobEvent| printer.show(e);
    let plan = job.plan(&mut show)?;
    let evaluation = plan.run(&mut show)?;
    print_evaluation(&evaluation, &plan.out, plan.n_frames())?;
    evaluation.check_finite()?;
    Ok(())
}

/// Prints an evaluation as a Markdown table and as JSON, then the files it wrote.
pub fn print_evaluation(evaluation: &Evaluation, out: &Path, n_frames: usize) -> Result<()> {
    let opt = |v: Option<f64>| v.map(|m| format!("{m:.2}")).unwrap_or_else(|| "-".into());
    println!(
        "| model | split | step | frames | head PSNR (dB) | head SSIM | mouth PSNR (dB) | whole-frame PSNR (dB) | whole-frame SSIM | repainted background (%) | GMAC / frame | s / frame |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    let opt4 = |v: Option<f64>| v.map(|m| format!("{m:.4}")).unwrap_or_else(|| "-".into());
    for r in &evaluation.models {
        println!(
            "| {} | {} | {} | {} | {} | {} | {} | {:.2} | {:.4} | {} | {:.2} | {:.2} |",
            r.model,
            r.split,
            r.step,
            r.frames.len(),
            opt(r.head_psnr),
            opt4(r.head_ssim),
            opt(r.mouth_psnr),
            r.psnr,
            r.ssim,
            r.repainted
                .map_or("-".into(), |v| format!("{:.1}", 100.0 * v)),
            r.macs_per_frame / 1e9,
            r.render_s_per_frame
        );
    }
    if evaluation.models.iter().any(|r| r.by_view.len() > 1) {
        println!();
        println!(
            "| model | view | frames | head PSNR (dB) | mouth PSNR (dB) | whole-frame PSNR (dB) |"
        );
        println!("|---|---|---|---|---|---|");
        for r in &evaluation.models {
            for v in &r.by_view {
                println!(
                    "| {} | {} | {} | {} | {} | {:.2} |",
                    r.model,
                    v.view,
                    v.frames,
                    opt(v.head_psnr),
                    opt(v.mouth_psnr),
                    v.psnr,
                );
            }
        }
    }
    let rows = evaluation
        .models
        .iter()
        .map(|r| {
            // The report as it serialises, with its frame count instead of every frame.
            let mut row = serde_json::to_value(r)?;
            if let Some(fields) = row.as_object_mut() {
                fields.insert("frames".into(), r.frames.len().into());
            }
            Ok(row)
        })
        .collect::<Result<Vec<serde_json::Value>>>()?;
    println!("{}", serde_json::to_string(&rows)?);
    println!("wrote to {}:", out.display());
    for r in &evaluation.models {
        println!("  {}/ ({} PNG)", out.join(&r.label).display(), n_frames);
    }
    for f in evaluation
        .files
        .iter()
        .filter(|f| f.extension().is_some_and(|e| e == "json") || f.ends_with("grid.png"))
    {
        println!("  {}", f.display());
    }
    Ok(())
}
