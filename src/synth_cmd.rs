//! `nldf synth`: the synthetic talking head as an AD-NeRF dataset.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use nldf_core::synth::{self, SynthConfig};

use crate::progress::progress_bar;

#[derive(clap::Args, Debug)]
pub struct SynthArgs {
    /// Output dataset folder (created; must be empty or absent unless --force).
    #[arg(long)]
    pub out: PathBuf,
    /// Seed of the head's look, its speech and its motion.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Length in seconds (with --audio: at most the file's length).
    #[arg(long)]
    pub seconds: Option<f32>,
    /// Image width and height in pixels.
    #[arg(long, default_value_t = 128)]
    pub size: u32,
    /// Drive the mouth with this WAV file instead of generated speech.
    #[arg(long)]
    pub audio: Option<PathBuf>,
    /// Sub-pixel rays per pixel along each axis (anti-aliasing).
    #[arg(long, default_value_t = 3)]
    pub supersample: u32,
    /// How far the `novel` evaluation split turns the head: this factor times the
    /// training frames' largest yaw and pitch.
    #[arg(long, default_value_t = 1.5)]
    pub novel_turn: f32,
    /// Seed of the `voice` evaluation split's speaker (default: --seed + 1).
    #[arg(long)]
    pub voice_seed: Option<u64>,
    /// Which head: `standard` (the one the recipes were tuned on, with nldf's exact region
    /// labels) or `second` (another shape and colouring, labelled as AD-NeRF labels a real
    /// recording: parsing without a mouth label, and 68 landmarks per frame).
    #[arg(long, value_enum, default_value_t = HeadArg::Standard)]
    pub head: HeadArg,
    /// Replace the output folder even if it holds something other than an earlier scene.
    #[arg(long)]
    pub force: bool,
}

/// `--head`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum HeadArg {
    Standard,
    Second,
}

impl HeadArg {
    /// The scene's head.
    pub fn style(self) -> synth::HeadStyle {
        match self {
            HeadArg::Standard => synth::HeadStyle::Standard,
            HeadArg::Second => synth::HeadStyle::Second,
        }
    }
}

pub fn run(args: SynthArgs) -> Result<()> {
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
        novel_turn: args.novel_turn,
        voice_seed: args.voice_seed,
        head: args.head.style(),
        ..default
    };
    synth::validate(&cfg)?;
    let bar = progress_bar(synth::frames_rendered(&cfg) as u64, "rendering frames");
    let start = Instant::now();
    let summary = synth::generate(&cfg, audio, &args.out, args.force, &|| bar.inc(1))
        .with_context(|| format!("generating the synthetic scene in {}", args.out.display()))?;
    bar.finish_and_clear();
    println!(
        "wrote {} frames ({} train, {} val, and {} of the novel, voice and sweep \
         evaluation splits) of {}x{} in {:.1} s to {}:",
        summary.n_frames,
        summary.n_train,
        summary.n_frames - summary.n_train,
        summary.n_eval,
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
