//! `nldf demo`: the whole pipeline on the embedded default, the synthetic talking head:
//! generate the scene, train the teacher within a time budget, distil the student from it,
//! evaluate both on the held-out frames and export the student as ONNX. Each stage that
//! already finished in the output folder is reused, and an interrupted stage resumes.

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
    let resume = teacher.join(nldf_core::run_files::MODEL_FILE).is_file();
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
            audio_features: crate::train_cmd::AudioFeaturesArg::Auto,
        },
        Some(args.minutes * 60.0),
    )?;
    if args.student_minutes > 0.0 {
        let student = args.out.join("student");
        let resume = student.join(nldf_core::run_files::MODEL_FILE).is_file();
        println!(
            "== student ({} min budget{}) -> {}",
            args.student_minutes,
            if resume { ", resuming" } else { "" },
            student.display()
        );
        crate::train_cmd::run_student(crate::train_cmd::StudentArgs {
            data: data.clone(),
            run: args.out.clone(),
            depth: args.student_depth,
            width: None,
            no_distill: false,
            no_pool: false,
            pseudo_frames: None,
            config: None,
            iters: Some(args.student_iters),
            minutes: Some(args.student_minutes),
            name: "student".into(),
            resume,
        })?;
        println!("== ONNX export");
        crate::export_cmd::run(crate::export_cmd::ExportArgs {
            run: args.out.clone(),
            out: None,
            fp16: false,
        })?;
    }
    println!("== evaluation on the held-out frames");
    crate::eval_cmd::run(EvalArgs {
        run: args.out.clone(),
        data,
        split: SplitArg::Val,
        frames: None,
        out: None,
    })
}
