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

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Synth(args) => run_synth(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
