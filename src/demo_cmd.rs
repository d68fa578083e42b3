//! `nldf demo`: the whole pipeline on the embedded default, the synthetic talking head:
//! generate the scene, train the teacher within a time budget, and evaluate it on the
//! held-out frames. Each stage that already finished in the output folder is reused, and an
//! interrupted teacher resumes.

use std::path::PathBuf;

use anyhow::Result;

use crate::eval_cmd::{EvalArgs, SplitArg};
use crate::synth_cmd::SynthArgs;
use crate::train_cmd::{TeacherArgs, TeacherPreset};

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
}

/// Runs `nldf demo`.
pub fn run(args: DemoArgs) -> Result<()> {
    if !(args.minutes.is_finite() && args.minutes > 0.0) {
        anyhow::bail!("--minutes must be positive, got {}", args.minutes);
    }
    let data = args.out.join("data");
    if data.join("scene.json").is_file() {
        println!("== synthetic scene: reusing {}", data.display());
    } else {
        println!("== synthetic scene -> {}", data.display());
        crate::synth_cmd::run(SynthArgs {
            out: data.clone(),
            seed: args.seed,
            seconds: None,
            size: 128,
            audio: None,
            supersample: 3,
            force: false,
        })?;
    }
    let teacher = args.out.join("teacher");
    let resume = teacher.join(nldf_train::checkpoint::MODEL_FILE).is_file();
    println!(
        "== teacher ({} min budget{}) -> {}",
        args.minutes,
        if resume { ", resuming" } else { "" },
        teacher.display()
    );
    crate::train_cmd::run_teacher_with(
        TeacherArgs {
            data: data.clone(),
            run: args.out.clone(),
            preset: TeacherPreset::Small,
            config: None,
            iters: None,
            resume,
        },
        Some(args.minutes * 60.0),
    )?;
    println!("== evaluation on the held-out frames");
    crate::eval_cmd::run(EvalArgs {
        run: args.out.clone(),
        data,
        split: SplitArg::Val,
        frames: None,
        out: None,
    })
}
