//! `nldf demo`: the whole pipeline on the embedded default, the synthetic talking head:
//! generate the scene, train the teacher within a time budget, train the student (on the
//! recorded pixels, or distilled from the teacher with `--distill`), export the student as
//! ONNX, evaluate both on the held-out frames, and render the student speaking with a
//! voice it never heard. Each stage that already finished in the output folder is reused,
//! and an interrupted stage resumes. It ends with a table of quality and speed and the
//! paths of the video, the comparison grid, the training curves and the model.

use std::path::{Path, PathBuf};

use anyhow::Result;
use nldf_core::run_files::{CURVE_FILE, STUDENT_DIR, TEACHER_DIR};
use nldf_core::synth::SynthConfig;
use nldf_infer::video::VideoReport;
use nldf_pipeline::demo::{DemoJob, DemoReport};
use nldf_pipeline::demo_video::plan_video;
use nldf_train::job::JobEvent;
use nldf_train::job::recipe::{
    DEMO_PIXELS_ITERS, DEMO_STUDENT_CAP_MINUTES, DEMO_TEACHER_CAP_MINUTES,
};

use crate::progress::{EventPrinter, progress_bar, stop_flag};

#[derive(clap::Args, Debug)]
pub struct DemoArgs {
    /// Run folder: the dataset goes to OUT/data, the teacher to OUT/teacher, the evaluations
    /// to OUT/eval/<split> [default: runs/demo, with --quick runs/demo_quick].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Seed of the synthetic scene.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    #[command(flatten)]
    pub stages: StageArgs,
    /// Student shape: the real-time preset (16 x 128, K = 8) renders in real time.
    #[arg(long, value_enum, default_value_t = crate::presets::StudentPreset::Realtime)]
    pub student_depth: crate::presets::StudentPreset,
    /// Train the student on the recorded pixels alone, without the teacher (the
    /// comparison: it breaks up beyond the recorded poses). By default it is distilled
    /// from the teacher with pseudo views at poses the recording lacks.
    #[arg(long)]
    pub pixels_only: bool,
    /// The synthetic head: `standard` (the one the recipe was tuned on) or `second`
    /// (another head, labelled as AD-NeRF labels a real recording).
    #[arg(long, value_enum, default_value_t = crate::synth_cmd::HeadArg::Standard)]
    pub head: crate::synth_cmd::HeadArg,
    /// A first look in a few minutes: a 64 x 64 scene of 4 s and few steps (far from
    /// converged; the default run is the one to judge quality by).
    #[arg(long)]
    pub quick: bool,
    /// Image width and height of the scene in pixels [default: 128, with --quick 64]. The
    /// recipe stays in steps: at another size its scores and times are not the table's.
    #[arg(long)]
    pub size: Option<u32>,
}

/// The steps and wall-clock caps of the recipe's two training stages, for `nldf demo` and
/// `nldf train --data`.
#[derive(clap::Args, Debug)]
pub struct StageArgs {
    /// The teacher: `grid` (a hash grid, sharper in the same minutes; its student takes
    /// eight times the steps) or `mlp` (AD-NeRF's, frequency-encoded; the quicker recipe).
    #[arg(long, value_enum, default_value_t = crate::presets::TeacherRecipe::default())]
    pub teacher: crate::presets::TeacherRecipe,
    /// Teacher training steps [default: 2400, the MLP teacher 1100; nldf demo --quick:
    /// 300].
    #[arg(long)]
    pub teacher_iters: Option<usize>,
    /// Student training steps (0 skips the student and the export) [default: 36000, under
    /// the MLP teacher 4500; nldf demo --pixels-only: 5300, --quick: 300].
    #[arg(long)]
    pub student_iters: Option<usize>,
    /// A wall-clock cap on the teacher in minutes: it only stops a machine slower than
    /// the recipe was sized for (and says so) [default: 7; nldf demo --quick: 2].
    #[arg(long)]
    pub minutes: Option<f64>,
    /// A wall-clock cap on the student in minutes, its teacher targets included
    /// [default: 75, under the MLP teacher 8; nldf demo --pixels-only: 15, --quick: 2].
    #[arg(long)]
    pub student_minutes: Option<f64>,
    /// Seed of the teacher's and the student's ray batches and initial weights: another
    /// value trains the same recipe again, to see how far two runs part.
    #[arg(long, default_value_t = 0)]
    pub train_seed: u64,
}

/// Runs `nldf demo`.
pub fn run(args: DemoArgs) -> Result<()> {
    run_job(job(&args)?, "nldf demo")
}

/// The job `nldf demo`'s flags ask for: the recipe of the chosen teacher, with the steps,
/// caps, size and folder the flags change.
fn job(args: &DemoArgs) -> Result<DemoJob> {
    let quick = args.quick;
    let pick = |full: f64, fast: f64| if quick { fast } else { full };
    let minutes = args
        .stages
        .minutes
        .unwrap_or(pick(DEMO_TEACHER_CAP_MINUTES, 2.0));
    let out = args.out.clone().unwrap_or_else(|| {
        PathBuf::from(if quick {
            "runs/demo_quick"
        } else {
            "runs/demo"
        })
    });
    let defaults = DemoJob::with_teacher(out, args.stages.teacher.kind());
    // The pixels-only student stands in for the teacher too: the caps of both.
    let student_minutes = args.stages.student_minutes.unwrap_or(pick(
        if args.pixels_only {
            DEMO_TEACHER_CAP_MINUTES + DEMO_STUDENT_CAP_MINUTES
        } else {
            defaults.student_cap_minutes
        },
        2.0,
    ));
    for (flag, v) in [
        ("--minutes", minutes),
        ("--student-minutes", student_minutes),
    ] {
        if !(v.is_finite() && v > 0.0) {
            anyhow::bail!("{flag} must be positive, got {v}");
        }
    }
    let mut scene = if quick {
        SynthConfig {
            seed: args.seed,
            head: args.head.style(),
            seconds: 4.0,
            size: 64,
            supersample: 1,
            ..defaults.scene.clone()
        }
    } else {
        SynthConfig {
            seed: args.seed,
            head: args.head.style(),
            ..defaults.scene.clone()
        }
    };
    if let Some(size) = args.size {
        scene.size = size;
        nldf_core::synth::validate(&scene)?;
    }
    let job = DemoJob {
        scene,
        teacher_iters: args.stages.teacher_iters.unwrap_or(if quick {
            300
        } else {
            defaults.teacher_iters
        }),
        teacher_cap_minutes: minutes,
        student: args.student_depth.config(),
        student_iters: args
            .stages
            .student_iters
            .unwrap_or(match (quick, args.pixels_only) {
                (true, _) => 300,
                (false, true) => DEMO_PIXELS_ITERS,
                (false, false) => defaults.student_iters,
            }),
        student_cap_minutes: student_minutes,
        student_distill: !args.pixels_only,
        train_seed: args.stages.train_seed,
        ..defaults
    };
    Ok(job)
}

/// Runs a demo job (the synthetic scene's, or `nldf train --data`'s on a dataset) with
/// progress, then prints the evaluation, renders the video and prints the closing table.
pub fn run_job(job: DemoJob, command: &str) -> Result<()> {
    job.check()?;
    // The kernels' path is what can move the scores between CPUs: the log says which ran.
    println!(
        "== training kernels: {} (NLDF_KERNELS forces avx512, avx2 or portable)",
        nldf_train::kernels::path().name()
    );
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
        Some(model) => Some(render_new_voice(&job.data_dir(), &job.out, model)?),
        None => None,
    };
    print_summary(command, &job.out, &report, video.as_ref());
    Ok(())
}

/// Renders the exported student at the held-out frames' poses into OUT/video (replacing an
/// earlier one's) with nldf-pipeline's [`plan_video`], with a progress bar.
fn render_new_voice(data: &Path, out: &Path, model: &Path) -> Result<VideoReport> {
    let (plan, voice) = plan_video(data, out, model)?;
    println!(
        "== rendering {} at the held-out poses -> {}",
        voice.describe(),
        out.join("video").display()
    );
    let bar = progress_bar(plan.n_frames() as u64, "frames");
    let report = plan.render(|p| bar.set_position(p.done as u64))?;
    bar.finish_and_clear();
    Ok(report)
}

/// The closing table: each model's steps, then per held-out split its head-region PSNR
/// beside its whole-frame PSNR, the mouth's PSNR per split, the share of the background
/// it repainted, and its speed; then the paths of what the demo made.
fn print_summary(command: &str, out: &Path, report: &DemoReport, video: Option<&VideoReport>) {
    println!("\n== {command}: done");
    let names: Vec<&str> = report.splits.iter().map(|(s, _)| s.name()).collect();
    let mut header = "| model | steps |".to_string();
    for n in &names {
        header.push_str(&format!(" {n}: head / whole PSNR (dB) |"));
    }
    header.push_str(&format!(
        " mouth PSNR (dB), {} | repainted background (%), {} | frames/s |",
        names.join(" / "),
        names.join(" / ")
    ));
    println!("{header}");
    println!("|{}", "---|".repeat(5 + names.len()));
    let opt = |v: Option<f64>| v.map_or("-".into(), |m| format!("{m:.2}"));
    for (mi, r) in report.evaluation.models.iter().enumerate() {
        let per_split =
            |f: &dyn Fn(&nldf_train::reports::eval::EvalReport) -> String| -> Vec<String> {
                report
                    .splits
                    .iter()
                    .map(|(_, e)| e.models.get(mi).map_or("-".into(), f))
                    .collect()
            };
        let scores = per_split(&|m| format!("{} / {:.2}", opt(m.head_psnr), m.psnr));
        let mouth = per_split(&|m| opt(m.mouth_psnr));
        let repainted = per_split(&|m| {
            m.repainted
                .map_or("-".into(), |v| format!("{:.1}", 100.0 * v))
        });
        let candle_fps = 1.0 / r.render_s_per_frame.max(1e-9);
        let fps = match video {
            Some(v) if r.label != "teacher" => format!(
                "{:.1} (ONNX, tract); {candle_fps:.1} (candle)",
                v.n_frames as f64 / v.render_seconds.max(1e-9)
            ),
            _ => format!("{candle_fps:.1} (candle)"),
        };
        println!(
            "| {} | {} | {} | {} | {} | {fps} |",
            r.model,
            r.step,
            scores.join(" | "),
            mouth.join(" / "),
            repainted.join(" / "),
        );
    }
    println!(
        "(head: the pixels of the exact head mask; whole: the frame, half of it background \
         copied from bc.png. Splits: val = held-out frames, novel = poses beyond the \
         recorded ones, voice = a voice never heard. frames/s of whole frames on this machine)"
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

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;
    use nldf_train::job::recipe::{
        DEMO_GRID_STUDENT_CAP_MINUTES, DEMO_GRID_STUDENT_ITERS, DEMO_GRID_TEACHER_ITERS,
        DEMO_STUDENT_ITERS, DEMO_TEACHER_ITERS,
    };

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        demo: DemoArgs,
    }

    fn demo_job(flags: &[&str]) -> DemoJob {
        let argv = [&["nldf"][..], flags].concat();
        job(&Cli::try_parse_from(argv).unwrap().demo).unwrap()
    }

    /// The default demo trains the grid teacher and its student for that student's own
    /// steps and cap; `--teacher mlp` the MLP teacher's; a flag still wins.
    #[test]
    fn the_demo_student_takes_its_teachers_steps() {
        let grid = demo_job(&[]);
        assert_eq!(grid.student_iters, DEMO_GRID_STUDENT_ITERS);
        assert_eq!(grid.student_cap_minutes, DEMO_GRID_STUDENT_CAP_MINUTES);
        assert_eq!(grid.teacher_iters, DEMO_GRID_TEACHER_ITERS);
        assert!(grid.teacher.grid.is_some());
        let mlp = demo_job(&["--teacher", "mlp"]);
        assert!(mlp.teacher.grid.is_none());
        assert_eq!(mlp.teacher_iters, DEMO_TEACHER_ITERS);
        assert_eq!(mlp.student_iters, DEMO_STUDENT_ITERS);
        assert_eq!(mlp.student_cap_minutes, DEMO_STUDENT_CAP_MINUTES);
        let set = demo_job(&["--student-iters", "7"]);
        assert_eq!(set.student_iters, 7);
        assert_eq!(set.train_seed, 0);
        assert_eq!(demo_job(&["--train-seed", "3"]).train_seed, 3);
        // The command line's default is the library's (`DemoJob::defaults`).
        assert_eq!(
            crate::presets::TeacherRecipe::default().kind(),
            nldf_train::job::recipe::TeacherKind::default()
        );
    }
}
