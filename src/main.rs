//! The `nldf` command line: a thin front end over the workspace's libraries.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use nldf_core::synth::{self, SynthConfig};

/// Audio-driven 3D talking heads that render fast (NLDF: a NeRF teacher distilled into a
/// light-field student, exported to ONNX, rendered on the CPU).
#[derive(Parser, Debug)]
#[command(name = "nldf", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Generate the synthetic talking head as an AD-NeRF dataset (frames, background, audio,
    /// audio features, camera poses, depth, parsing masks and scene.json ground truth).
    Synth(SynthArgs),
    /// Train a stage of the pipeline (the teacher NeRF).
    #[command(subcommand)]
    Train(TrainCommand),
}

#[derive(Subcommand, Debug)]
enum TrainCommand {
    /// Train the audio-conditioned NeRF teacher on a dataset.
    Teacher(TeacherArgs),
}

/// Teacher presets.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
enum TeacherPreset {
    /// 6 x 128, 32 samples inside the head's bounds: for 2-core machines.
    Small,
    /// AD-NeRF's 8 x 256 with 64 + 128 samples.
    AdNerf,
    /// 2 x 32, for tests and smoke runs.
    Tiny,
}

#[derive(clap::Args, Debug)]
struct TeacherArgs {
    /// Dataset folder in AD-NeRF's layout (e.g. one written by `nldf synth`).
    #[arg(long)]
    data: PathBuf,
    /// Run folder; the teacher goes to RUN/teacher.
    #[arg(long)]
    run: PathBuf,
    /// Network preset (ignored with --config or --resume).
    #[arg(long, value_enum, default_value_t = TeacherPreset::Small)]
    preset: TeacherPreset,
    /// JSON run configuration ({"model": {...}, "train": {...}}; missing fields take the
    /// defaults).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Total training steps (overrides the configuration; with --resume, extends the run).
    #[arg(long)]
    iters: Option<usize>,
    /// Continue the run in RUN/teacher from its last checkpoint.
    #[arg(long)]
    resume: bool,
}

#[derive(clap::Args, Debug)]
struct SynthArgs {
    /// Output dataset folder (created; must be empty or absent unless --force).
    #[arg(long)]
    out: PathBuf,
    /// Seed of the head's look, its speech and its motion.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Length in seconds (with --audio: at most the file's length).
    #[arg(long)]
    seconds: Option<f32>,
    /// Image width and height in pixels.
    #[arg(long, default_value_t = 128)]
    size: u32,
    /// Drive the mouth with this WAV file instead of generated speech.
    #[arg(long)]
    audio: Option<PathBuf>,
    /// Sub-pixel rays per pixel along each axis (anti-aliasing).
    #[arg(long, default_value_t = 3)]
    supersample: u32,
    /// Replace the output folder even if it holds something other than an earlier scene.
    #[arg(long)]
    force: bool,
}

fn progress_bar(len: u64, what: &str) -> ProgressBar {
    let bar = ProgressBar::new(len);
    let style = ProgressStyle::with_template(
        "{msg} [{bar:40.cyan/blue}] {pos}/{len} ({per_sec}, eta {eta})",
    )
    .unwrap_or_else(|_| ProgressStyle::default_bar())
    .progress_chars("=> ");
    bar.set_style(style);
    bar.set_message(what.to_string());
    bar
}

fn run_synth(args: SynthArgs) -> Result<()> {
    let audio = match &args.audio {
        Some(path) => Some(nldf_core::audio::read_wav(path)?),
        None => None,
    };
    let default = SynthConfig::default();
    let seconds = match (&audio, args.seconds) {
        (_, Some(s)) => s,
        (Some(w), None) => w.samples.len() as f32 / w.sample_rate as f32,
        (None, None) => default.seconds,
    };
    let cfg = SynthConfig {
        seed: args.seed,
        seconds,
        size: args.size,
        supersample: args.supersample,
        ..default
    };
    synth::validate(&cfg)?;
    let n_frames = (seconds * 25.0).floor() as u64;
    let bar = progress_bar(n_frames, "rendering frames");
    let start = Instant::now();
    let summary = synth::generate(&cfg, audio, &args.out, args.force, &|| bar.inc(1))
        .with_context(|| format!("generating the synthetic scene in {}", args.out.display()))?;
    bar.finish_and_clear();
    println!(
        "wrote {} frames ({} train, {} val) of {}x{} in {:.1} s to {}:",
        summary.n_frames,
        summary.n_train,
        summary.n_frames - summary.n_train,
        cfg.size,
        cfg.size,
        start.elapsed().as_secs_f32(),
        summary.out.display()
    );
    for (path, count) in &summary.files {
        let path = summary.out.join(path);
        if *count == 1 {
            println!("  {}", path.display());
        } else {
            println!("  {}/ ({count} files)", path.display());
        }
    }
    Ok(())
}

fn run_train_teacher(args: TeacherArgs) -> Result<()> {
    use nldf_train::config::{TeacherConfig, TeacherRunConfig};
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
                model: match args.preset {
                    TeacherPreset::Small => TeacherConfig::small(),
                    TeacherPreset::AdNerf => TeacherConfig::ad_nerf(),
                    TeacherPreset::Tiny => TeacherConfig::tiny(),
                },
                ..TeacherRunConfig::default()
            },
        };
        if let Some(n) = args.iters {
            cfg.train.iters = n;
        }
        nldf_train::trainer::validate(&cfg)?;
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
                scores
                    .mouth_psnr
                    .map(|m| format!(", mouth PSNR {m:.2} dB"))
                    .unwrap_or_default()
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
    ] {
        println!("  {}", dir.join(f).display());
    }
    Ok(())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Synth(args) => run_synth(args),
        Command::Train(TrainCommand::Teacher(args)) => run_train_teacher(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
