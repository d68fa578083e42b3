//! `nldf features`: a WAV file's audio features made with nldf's front end, written as an
//! AD-NeRF `aud.npy` (`[N, 16, F]`, one window per video frame) with `aud.json` beside it
//! saying how they were made, so that a dataset trains on features that any WAV can be
//! turned into at render time.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use nldf_core::audio::{FeatureConfig, FeatureSource, audio_windows, read_wav};
use nldf_core::dataset::save_audio_npy;

#[derive(clap::Args, Debug)]
pub struct FeaturesArgs {
    /// The speech: a WAV file (any rate, mono or stereo).
    #[arg(long)]
    pub audio: PathBuf,
    /// The windows' file; the settings go beside it with the extension `.json`
    /// (`aud.npy` and `aud.json` in a dataset folder).
    #[arg(long)]
    pub out: PathBuf,
    /// Video frames per second: one window per frame.
    #[arg(long, default_value_t = 25.0)]
    pub fps: f32,
    /// Mel bands per feature frame, the F of [N, 16, F].
    #[arg(long, default_value_t = FeatureConfig::default().n_mels)]
    pub n_mels: usize,
}

/// Runs `nldf features`.
pub fn run(args: FeaturesArgs) -> Result<()> {
    if !(args.fps.is_finite() && args.fps > 0.0) {
        bail!("--fps must be positive, got {}", args.fps);
    }
    if args.out.extension().is_none_or(|e| e != "npy") {
        bail!(
            "--out {}: the windows' file must end in .npy",
            args.out.display()
        );
    }
    let cfg = FeatureConfig {
        n_mels: args.n_mels,
        ..FeatureConfig::default()
    };
    cfg.validate().context("--n-mels")?;
    let wave = read_wav(&args.audio)?;
    let windows = audio_windows(&wave, args.fps, &cfg)?;
    if windows.n_frames == 0 {
        bail!(
            "{}: {:.3} s of audio is shorter than one video frame (1/{} s)",
            args.audio.display(),
            wave.seconds(),
            args.fps
        );
    }
    if let Some(dir) = args.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let sidecar = args.out.with_extension("json");
    save_audio_npy(&args.out, &windows)?;
    nldf_core::files::write_json(&sidecar, &FeatureSource::Nldf(cfg.clone()))?;
    println!(
        "{} video frames at {} fps from {:.2} s of {}: [{}, {}, {}] windows of {}",
        windows.n_frames,
        args.fps,
        wave.seconds(),
        args.audio.display(),
        windows.n_frames,
        windows.window,
        windows.n_features,
        FeatureSource::Nldf(cfg).describe()
    );
    println!("wrote {}", args.out.display());
    println!("wrote {}", sidecar.display());
    Ok(())
}
