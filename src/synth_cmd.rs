//! `nldf synth`: the synthetic talking head as an AD-NeRF dataset, and with `--video` the
//! same recording as an MP4, a test video whose truth (poses, masks, background, mouth) is
//! the dataset.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use nldf_core::dataset::{Split, TransformsFile};
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
    /// Render at this size (its detail: at 512 the hat's stripes, the irises and the teeth
    /// show), then shrink every image, label and intrinsic to --size, as `nldf prepare`
    /// shrinks a dataset analysed at a larger size. Default: --size.
    #[arg(long)]
    pub render_size: Option<u32>,
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
    /// The camera's focal length in pixels of a 128-pixel frame (scaled with --size); a
    /// shorter one widens the view (330: 22 degrees across).
    #[arg(long, default_value_t = SynthConfig::default().focal_at_128)]
    pub focal_at_128: f32,
    /// The camera's distance from the head's centre (at least 0.5); with --focal-at-128 it
    /// sets how large the head is and how strong the perspective.
    #[arg(long, default_value_t = SynthConfig::default().camera_distance)]
    pub camera_distance: f32,
    /// Largest head turn (yaw) in degrees, at most 45; the largest pitch and roll are 0.6
    /// and 0.4 of it.
    #[arg(long, default_value_t = SynthConfig::default().max_yaw_deg)]
    pub max_yaw_deg: f32,
    /// Also write the recording (the train and val frames, in order, with `aud.wav`) as
    /// this MP4: H.264 (yuv420p, CRF 14) at the scene's constant frame rate with AAC audio,
    /// made by the ffmpeg `nldf prepare` uses. The dataset is its truth. Needs an even
    /// --size.
    #[arg(long)]
    pub video: Option<PathBuf>,
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
    // A larger --render-size is the size the scene renders at; its check would name --size.
    if let Some(r) = args
        .render_size
        .filter(|&r| r > args.size && !synth::SIZES.contains(&r))
    {
        bail!(
            "--render-size must be in {}..={} pixels, got {r}",
            synth::SIZES.start(),
            synth::SIZES.end()
        );
    }
    let cfg = SynthConfig {
        seed: args.seed,
        seconds,
        size: args.render_size.unwrap_or(args.size).max(args.size),
        supersample: args.supersample,
        novel_turn: args.novel_turn,
        voice_seed: args.voice_seed,
        max_yaw_deg: args.max_yaw_deg,
        focal_at_128: args.focal_at_128,
        camera_distance: args.camera_distance,
        head: args.head.style(),
        ..default
    };
    synth::validate(&cfg)?;
    let ffmpeg = match &args.video {
        Some(video) => Some(video_plan(video, args.size)?),
        None => None,
    };
    let bar = progress_bar(synth::frames_rendered(&cfg) as u64, "rendering frames");
    let start = Instant::now();
    let summary = synth::generate(&cfg, audio, &args.out, args.force, &|| bar.inc(1))
        .with_context(|| format!("generating the synthetic scene in {}", args.out.display()))?;
    bar.finish_and_clear();
    if cfg.size > args.size {
        nldf_prepare::resample::shrink_dataset(&summary.out, cfg.size, args.size)
            .with_context(|| format!("shrinking the scene in {}", summary.out.display()))?;
    }
    println!(
        "wrote {} frames ({} train, {} val, and {} of the novel, voice and sweep \
         evaluation splits) of {}x{} in {:.1} s to {}:",
        summary.n_frames,
        summary.n_train,
        summary.n_frames - summary.n_train,
        summary.n_eval,
        args.size,
        args.size,
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
    if let (Some(video), Some(ffmpeg)) = (&args.video, &ffmpeg) {
        let n = mux_recording(ffmpeg, &summary.out, video, cfg.fps)?;
        println!(
            "wrote {} ({n} frames at {} fps with aud.wav)",
            video.display(),
            cfg.fps
        );
    }
    Ok(())
}

/// Checks `--video` before any frame is rendered; returns the ffmpeg to mux with.
fn video_plan(video: &Path, size: u32) -> Result<PathBuf> {
    if !size.is_multiple_of(2) {
        bail!("--video needs an even --size (H.264 in yuv420p), got {size}");
    }
    if video.is_dir() {
        bail!("--video {}: is a folder, not a file", video.display());
    }
    let ffmpeg = nldf_prepare::tools::ffmpeg().context("--video needs ffmpeg")?;
    Ok(ffmpeg)
}

/// Muxes the recording of the dataset at `root` (the train and val frames, which must be
/// `head_imgs/0.png` to `head_imgs/<n-1>.png`, one continuous clip) with `aud.wav` into
/// `video` at `fps`, atomically: ffmpeg writes a temporary file beside it, renamed only on
/// success. Returns the number of frames.
fn mux_recording(ffmpeg: &Path, root: &Path, video: &Path, fps: f32) -> Result<usize> {
    let mut ids = Vec::new();
    for split in [Split::Train, Split::Val] {
        let t = TransformsFile::load(&root.join(split.file_name()))?;
        ids.extend(t.frames.iter().map(|f| f.img_id));
    }
    ids.sort_unstable();
    if ids.iter().enumerate().any(|(k, &id)| id != k as i64) {
        bail!(
            "{}: the train and val frames are not one clip from img_id 0",
            root.display()
        );
    }
    let name = video
        .file_name()
        .with_context(|| format!("--video {}: not a file path", video.display()))?;
    let dir = video
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let tmp = dir.join(format!(
        ".{}.partial-{}",
        name.to_string_lossy(),
        std::process::id()
    ));
    let written = run_ffmpeg(ffmpeg, root, &tmp, fps, ids.len())
        .and_then(|()| std::fs::rename(&tmp, video).context("renaming the video into place"));
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written.with_context(|| format!("writing {}", video.display()))?;
    Ok(ids.len())
}

/// ffmpeg: `n_frames` frames of `root/head_imgs/%d.png` from 0 at `fps`, and `root/aud.wav`,
/// into the MP4 `out`.
fn run_ffmpeg(ffmpeg: &Path, root: &Path, out: &Path, fps: f32, n_frames: usize) -> Result<()> {
    let result = Command::new(ffmpeg)
        .args(["-nostdin", "-y", "-loglevel", "error", "-framerate"])
        .arg(format!("{fps}"))
        .args(["-start_number", "0", "-i"])
        .arg(root.join("head_imgs/%d.png"))
        .arg("-i")
        .arg(root.join("aud.wav"))
        .args(["-map", "0:v", "-map", "1:a", "-frames:v"])
        .arg(n_frames.to_string())
        .args(["-c:v", "libx264", "-pix_fmt", "yuv420p", "-crf", "14"])
        .args([
            "-c:a",
            "aac",
            "-b:a",
            "128k",
            "-movflags",
            "+faststart",
            "-f",
            "mp4",
        ])
        .arg(out)
        .output()
        .with_context(|| format!("running {}", ffmpeg.display()))?;
    if !result.status.success() {
        let stderr = String::from_utf8_lossy(&result.stderr);
        bail!(
            "ffmpeg failed: {}",
            stderr.lines().next().unwrap_or("no message")
        );
    }
    Ok(())
}
