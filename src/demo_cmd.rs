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
    /// to OUT/eval/val.
    #[arg(long, default_value = "runs/demo")]
    pub out: PathBuf,
    /// Seed of the synthetic scene.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Teacher training budget in minutes of wall-clock time.
    #[arg(long, default_value_t = 20.0)]
    pub minutes: f64,
    /// Student training budget in minutes (its teacher targets included; 0 skips the
    /// student and the export).
    #[arg(long, default_value_t = 20.0)]
    pub student_minutes: f64,
    /// Student depth (28 trains about three times as many steps as 88 in the same time on
    /// a 2-core machine).
    #[arg(long, value_enum, default_value_t = crate::train_cmd::StudentDepth::D28)]
    pub student_depth: crate::train_cmd::StudentDepth,
    /// Student training steps (the learning rate decays over them; the budget may end
    /// the run first).
    #[arg(long, default_value_t = 3000)]
    pub student_iters: usize,
}

/// Runs `nldf demo`.
pub fn run(args: DemoArgs) -> Result<()> {
    if !(args.minutes.is_finite() && args.minutes > 0.0) {
        anyhow::bail!("--minutes must be positive, got {}", args.minutes);
    }
    if !(args.student_minutes.is_finite() && args.student_minutes >= 0.0) {
        anyhow::bail!(
            "--student-minutes must be zero or positive, got {}",
            args.student_minutes
        );
    }
    let job = DemoJob {
        out: args.out.clone(),
        scene: SynthConfig {
            seed: args.seed,
            size: 128,
            supersample: 3,
            ..SynthConfig::default()
        },
        teacher: TeacherPreset::Small.config(),
        teacher_minutes: args.minutes,
        student: args.student_depth.config(),
        student_minutes: args.student_minutes,
        student_iters: args.student_iters,
    };
    job.check()?;
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
