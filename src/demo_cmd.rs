//! `nldf demo`: the whole pipeline on the embedded default, the synthetic talking head:
//! generate the scene, train the teacher within a time budget, distil the student from it,
//! evaluate both on the held-out frames and export the student as ONNX. Each stage that
//! already finished in the output folder is reused, and an interrupted stage resumes.

use std::path::PathBuf;

use anyhow::Result;
use nldf_core::synth::SynthConfig;
use nldf_train::job::JobEvent;
use nldf_train::job::demo::DemoJob;

use crate::progress::{EventPrinter, stop_flag};
use crate::train_cmd::TeacherPreset;

#[derive(clap::Args, Debug)]
pub struct DemoArgs {
    /// Run folder: the dataset goes to OUT/data, the teacher to OUT/teacher, the evaluation
    /// to OUT/eval/val [default: runs/demo, with --quick runs/demo_quick].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Seed of the synthetic scene.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Teacher training budget in minutes of wall-clock time [default: 20, with --quick
    /// 1].
    #[arg(long)]
    pub minutes: Option<f64>,
    /// Student training budget in minutes (its teacher targets included; 0 skips the
    /// student and the export) [default: 20, with --quick 1].
    #[arg(long)]
    pub student_minutes: Option<f64>,
    /// Student depth (28 trains about three times as many steps as 88 in the same time on
    /// a 2-core machine).
    #[arg(long, value_enum, default_value_t = crate::train_cmd::StudentDepth::D28)]
    pub student_depth: crate::train_cmd::StudentDepth,
    /// Student training steps (the learning rate decays over them; the budget may end
    /// the run first) [default: 3000, with --quick 400].
    #[arg(long)]
    pub student_iters: Option<usize>,
    /// A first look in a few minutes: a 64 x 64 scene of 4 s and short budgets (far from
    /// converged; the default run is the one to judge quality by).
    #[arg(long)]
    pub quick: bool,
}

/// Runs `nldf demo`.
pub fn run(args: DemoArgs) -> Result<()> {
    let quick = args.quick;
    let pick = |full: f64, fast: f64| if quick { fast } else { full };
    let minutes = args.minutes.unwrap_or(pick(20.0, 1.0));
    let student_minutes = args.student_minutes.unwrap_or(pick(20.0, 1.0));
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
    let scene = if quick {
        SynthConfig {
            seed: args.seed,
            seconds: 4.0,
            size: 64,
            supersample: 1,
            ..SynthConfig::default()
        }
    } else {
        SynthConfig {
            seed: args.seed,
            size: 128,
            supersample: 3,
            ..SynthConfig::default()
        }
    };
    let job = DemoJob {
        out,
        scene,
        teacher: TeacherPreset::Small.config(),
        teacher_minutes: minutes,
        student: args.student_depth.config(),
        student_minutes,
        student_iters: args.student_iters.unwrap_or(if quick { 400 } else { 3000 }),
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
    Ok(())
}
