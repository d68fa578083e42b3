//! `nldf demo`: the whole pipeline on the embedded default, the synthetic talking head:
//! generate the scene, train the teacher within a time budget, train the student (on the
//! recorded pixels, or distilled from the teacher with `--distill`), export the student as
//! ONNX, evaluate both on the held-out frames, and render the student speaking with a
//! voice it never heard. Each stage that already finished in the output folder is reused,
//! and an interrupted stage resumes. It ends with a table of quality and speed and the
//! paths of the video, the comparison grid, the training curves and the model.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use nldf_core::dataset::{AUDIO_WAV, Split, VOICE_DIR};
use nldf_core::run_files::{CURVE_FILE, STUDENT_DIR, TEACHER_DIR};
use nldf_core::synth::SynthConfig;
use nldf_infer::backend::{BackendKind, BackendOptions};
use nldf_infer::video::{VideoJob, VideoReport};
use nldf_train::job::JobEvent;
use nldf_train::job::demo::{
    DEMO_STUDENT_ITERS, DEMO_STUDENT_MINUTES, DEMO_TEACHER_MINUTES, DemoJob, DemoReport,
};

use crate::progress::{EventPrinter, progress_bar, stop_flag};

#[derive(clap::Args, Debug)]
pub struct DemoArgs {
    /// Run folder: the dataset goes to OUT/data, the teacher to OUT/teacher, the evaluation
    /// to OUT/eval/val [default: runs/demo, with --quick runs/demo_quick].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Seed of the synthetic scene.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Teacher training budget in minutes of wall-clock time [default: 5, with --quick
    /// 1].
    #[arg(long)]
    pub minutes: Option<f64>,
    /// Student training budget in minutes (with --distill, its teacher targets included;
    /// 0 skips the student and the export) [default: 8.5, with --quick 1].
    #[arg(long)]
    pub student_minutes: Option<f64>,
    /// Student shape: the real-time preset (16 x 128, K = 8) trains about six times the
    /// steps of 28 x 256 in the same time and reaches more within the demo's minutes.
    #[arg(long, value_enum, default_value_t = crate::train_cmd::StudentDepth::Realtime)]
    pub student_depth: crate::train_cmd::StudentDepth,
    /// Student training steps: the learning rate is held for 60 % of the budget, then
    /// decays tenfold, or decays over these steps if they end first [default: 100000
    /// (the budget decides), with --quick 400].
    #[arg(long)]
    pub student_iters: Option<usize>,
    /// Distil the student from the teacher's segment colours. Without it the student
    /// learns the recorded pixels alone, which reaches more on the recorded poses in the
    /// demo's minutes (rendering the teacher's targets takes two of them); distillation
    /// with pseudo views is what holds up beyond the recorded poses (`nldf ablate
    /// --posed-minutes`).
    #[arg(long)]
    pub distill: bool,
    /// A first look in a few minutes: a 64 x 64 scene of 4 s and short budgets (far from
    /// converged; the default run is the one to judge quality by).
    #[arg(long)]
    pub quick: bool,
}

/// Runs `nldf demo`.
pub fn run(args: DemoArgs) -> Result<()> {
    let quick = args.quick;
    let pick = |full: f64, fast: f64| if quick { fast } else { full };
    let minutes = args.minutes.unwrap_or(pick(DEMO_TEACHER_MINUTES, 1.0));
    let student_minutes = args
        .student_minutes
        .unwrap_or(pick(DEMO_STUDENT_MINUTES, 1.0));
    if !(minutes.is_finite() && minutes > 0.0) {
        anyhow::bail!("--minutes must be positive, got {minutes}");
    }
    if !(student_minutes.is_finite() && student_minutes >= 0.0) {
        anyhow::bail!("--student-minutes must be zero or positive, got {student_minutes}");
    }
    let out = args.out.clone().unwrap_or_else(|| {
        PathBuf::from(if quick {
            "runs/demo_quick"
        } else {
            "runs/demo"
        })
    });
    let defaults = DemoJob::defaults(out);
    let scene = if quick {
        SynthConfig {
            seed: args.seed,
            seconds: 4.0,
            size: 64,
            supersample: 1,
            ..defaults.scene.clone()
        }
    } else {
        SynthConfig {
            seed: args.seed,
            ..defaults.scene.clone()
        }
    };
    let job = DemoJob {
        scene,
        teacher_minutes: minutes,
        student: args.student_depth.config(),
        student_minutes,
        student_iters: args
            .student_iters
            .unwrap_or(if quick { 400 } else { DEMO_STUDENT_ITERS }),
        student_distill: args.distill || defaults.student_distill,
        ..defaults
    };
    let stop = stop_flag();
    let mut printer = EventPrinter::default();
    let mut show = |e: &JobEvent| printer.show(e);
    let Some(report) = job.run(&stop, &mut show)? else {
        println!("interrupted; run the same command again to resume");
        return Ok(());
    };
    let n = report
        .evaluation
        .models
        .first()
        .map_or(0, |m| m.frames.len());
    crate::eval_cmd::print_evaluation(&report.evaluation, &report.eval_dir, n)?;
    report.evaluation.check_finite()?;
    let video = match &report.model {
        Some(model) => Some(render_new_voice(&job.out, model)?),
        None => None,
    };
    print_summary(&job.out, &report, video.as_ref());
    Ok(())
}

/// Renders the exported student speaking with the `voice` split's speaker, a voice it never
/// heard, at the held-out frames' poses, into OUT/video (replacing an earlier demo's), with
/// tract: an MP4 when ffmpeg is found, PNG frames always.
fn render_new_voice(out: &Path, model: &Path) -> Result<VideoReport> {
    let data = out.join("data");
    let video = out.join("video");
    if video.exists() {
        std::fs::remove_dir_all(&video)
            .with_context(|| format!("removing the earlier demo video {}", video.display()))?;
    }
    println!(
        "== rendering a voice the student never heard -> {}",
        video.display()
    );
    let job = VideoJob {
        model: model.to_path_buf(),
        audio: Some(data.join(VOICE_DIR).join(AUDIO_WAV)),
        features: None,
        poses: Some(data.join(Split::Val.file_name())),
        out: video,
        backend: BackendKind::Tract,
        options: BackendOptions::default(),
        size: None,
        mp4: true,
        ffmpeg: None,
        skip: None,
    };
    let plan = job.plan()?;
    let bar = progress_bar(plan.n_frames() as u64, "frames");
    let report = plan.render(|p| bar.set_position(p.done as u64))?;
    bar.finish_and_clear();
    Ok(report)
}

/// The closing table (teacher and student quality on the held-out frames, and speed) and
/// the paths of what the demo made.
fn print_summary(out: &Path, report: &DemoReport, video: Option<&VideoReport>) {
    println!("\n== nldf demo: done");
    println!(
        "| model | step | head PSNR (dB) | head SSIM | mouth PSNR (dB) | whole-frame PSNR (dB) | frames/s |"
    );
    println!("|---|---|---|---|---|---|---|");
    for r in &report.evaluation.models {
        let opt = |v: Option<f64>, digits: usize| v.map_or("-".into(), |m| format!("{m:.digits$}"));
        let candle_fps = 1.0 / r.render_s_per_frame.max(1e-9);
        let fps = match video {
            Some(v) if r.label != "teacher" => format!(
                "{:.1} (ONNX, tract); {candle_fps:.1} (candle)",
                v.n_frames as f64 / v.render_seconds.max(1e-9)
            ),
            _ => format!("{candle_fps:.1} (candle)"),
        };
        println!(
            "| {} | {} | {} | {} | {} | {:.2} | {fps} |",
            r.model,
            r.step,
            opt(r.head_psnr, 2),
            opt(r.head_ssim, 4),
            opt(r.mouth_psnr, 2),
            r.psnr
        );
    }
    println!(
        "(scores over the {} held-out frames; frames/s of whole frames on this machine)",
        report
            .evaluation
            .models
            .first()
            .map_or(0, |m| m.frames.len())
    );
    let show = |what: &str, path: PathBuf| println!("  {what:<16} {}", path.display());
    if let Some(v) = video {
        match &v.video {
            Some(mp4) => show("video", mp4.clone()),
            None => show("video frames", v.out.clone()),
        }
    }
    show("comparison grid", report.eval_dir.join("grid.png"));
    show("teacher curve", out.join(TEACHER_DIR).join(CURVE_FILE));
    if let Some(model) = &report.model {
        show("student curve", out.join(STUDENT_DIR).join(CURVE_FILE));
        show("model", model.clone());
    }
    show("scores", report.eval_dir.join("metrics.json"));
}
