//! `nldf train`: the teacher (and, later, the student) trainers with progress, logging,
//! checkpoints and Ctrl-C handling.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Subcommand;

use crate::progress::progress_bar;

#[derive(Subcommand, Debug)]
pub enum TrainCommand {
    /// Train the audio-conditioned NeRF teacher on a dataset.
    Teacher(TeacherArgs),
}

/// Teacher presets.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum TeacherPreset {
    /// 6 x 128, 32 samples inside the head's bounds: for 2-core machines.
    Small,
    /// AD-NeRF's 8 x 256 with 64 + 128 samples.
    AdNerf,
    /// 2 x 32, for tests and smoke runs.
    Tiny,
}

#[derive(clap::Args, Debug)]
pub struct TeacherArgs {
    /// Dataset folder in AD-NeRF's layout (e.g. one written by `nldf synth`).
    #[arg(long)]
    pub data: PathBuf,
    /// Run folder; the teacher goes to RUN/teacher.
    #[arg(long)]
    pub run: PathBuf,
    /// Network preset (ignored with --config or --resume).
    #[arg(long, value_enum, default_value_t = TeacherPreset::Small)]
    pub preset: TeacherPreset,
    /// JSON run configuration ({"model": {...}, "train": {...}}; missing fields take the
    /// defaults).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Total training steps (overrides the configuration; with --resume, extends the run).
    #[arg(long)]
    pub iters: Option<usize>,
    /// Continue the run in RUN/teacher from its last checkpoint.
    #[arg(long)]
    pub resume: bool,
}

impl TeacherPreset {
    /// The preset's network configuration.
    pub fn config(self) -> nldf_train::config::TeacherConfig {
        use nldf_train::config::TeacherConfig;
        match self {
            TeacherPreset::Small => TeacherConfig::small(),
            TeacherPreset::AdNerf => TeacherConfig::ad_nerf(),
            TeacherPreset::Tiny => TeacherConfig::tiny(),
        }
    }
}

/// Runs a `nldf train` subcommand.
pub fn run(cmd: TrainCommand) -> Result<()> {
    match cmd {
        TrainCommand::Teacher(args) => run_teacher_with(args, None),
    }
}

/// Trains (or resumes) a teacher; `budget_s` caps its training time.
pub fn run_teacher_with(args: TeacherArgs, budget_s: Option<f64>) -> Result<()> {
    use nldf_train::config::TeacherRunConfig;
    use nldf_train::trainer::{Event, TeacherRun, TrainData};
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};

    let dir = args.run.join("teacher");
    let exists = dir.join(nldf_train::checkpoint::MODEL_FILE).is_file();
    if exists && !args.resume {
        anyhow::bail!(
            "{} already holds a teacher; pass --resume to continue it or choose another --run",
            dir.display()
        );
    }
    if args.resume && !exists {
        anyhow::bail!("{} holds no teacher checkpoint to resume", dir.display());
    }
    let cfg = if args.resume {
        None
    } else {
        let mut cfg = match &args.config {
            Some(path) => nldf_train::checkpoint::load_json::<TeacherRunConfig>(path)?,
            None => TeacherRunConfig {
                model: args.preset.config(),
                ..TeacherRunConfig::default()
            },
        };
        if let Some(n) = args.iters {
            cfg.train.iters = n;
        }
        nldf_train::trainer::validate(&cfg).with_context(|| match &args.config {
            Some(path) => format!("{}: invalid configuration", path.display()),
            None => "invalid configuration".to_string(),
        })?;
        Some(cfg)
    };

    eprintln!("loading {}", args.data.display());
    let data = TrainData::load(&args.data)?;
    let mut run = match cfg {
        Some(cfg) => TeacherRun::create(&dir, cfg, &data)?,
        None => {
            let mut run = TeacherRun::open(&dir, true)?;
            if let Some(n) = args.iters {
                run.cfg.train.iters = n;
            }
            eprintln!("resuming at step {}", run.step);
            run
        }
    };
    if let Some(b) = budget_s {
        run.cfg.train.time_budget_s = b;
    }
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        ctrlc::set_handler(move || stop.store(true, Ordering::Relaxed))
            .context("installing the Ctrl-C handler")?;
    }
    let total = run.cfg.train.iters as u64;
    let bar = progress_bar(total, "teacher");
    bar.set_position(run.step as u64);
    let mut last_val = String::new();
    let scores = run.train(&data, &stop, &mut |e| match e {
        Event::Step {
            step,
            loss,
            psnr,
            rays_per_s,
        } => {
            bar.set_position(*step as u64);
            bar.set_message(format!(
                "teacher loss {loss:.2e} psnr {psnr:.2} dB {rays_per_s:.0} rays/s{last_val}"
            ));
        }
        Event::Validation { step, scores } => {
            last_val = format!(" | val {:.2} dB", scores.psnr);
            bar.println(format!(
                "step {step}: validation PSNR {:.2} dB, SSIM {:.4}{}",
                scores.psnr,
                scores.ssim,
                match (scores.face_psnr, scores.mouth_psnr) {
                    (Some(f), Some(m)) => format!(", face {f:.2} dB, mouth {m:.2} dB"),
                    _ => String::new(),
                }
            ));
        }
        Event::Checkpoint { .. } => {}
    })?;
    bar.finish_and_clear();
    if stop.load(Ordering::Relaxed) {
        println!(
            "interrupted at step {}; checkpoint written, continue with --resume",
            run.step
        );
    }
    if let Some(s) = scores {
        println!(
            "{}",
            serde_json::to_string(&serde_json::json!({"step": run.step, "val": s}))?
        );
    }
    println!("wrote to {}:", dir.display());
    for f in [
        "config.json",
        "model.safetensors",
        "train_state.safetensors",
        "log.csv",
        "training_curve.png",
    ] {
        println!("  {}", dir.join(f).display());
    }
    Ok(())
}
