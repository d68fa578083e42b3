//! `nldf render`: a talking-head video from an exported model and a WAV file, on the CPU
//! with tract or onnxruntime: PNG frames, and an MP4 with the audio when ffmpeg is on the
//! PATH. With `--stream`, the WAV is read as it arrives (stdin or a named pipe) and each
//! frame is written as soon as its audio is in, with bounded latency.

use std::path::PathBuf;

use anyhow::Result;
use nldf_infer::backend::{BackendKind, BackendOptions};
use nldf_infer::still::SkipConfig;
use nldf_infer::stream::{STREAM_REPORT_FILE, StreamJob};
use nldf_infer::video::VideoJob;

use crate::progress::progress_bar;

/// The runtime that evaluates the network.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum BackendArg {
    /// tract, pure Rust (needs nothing installed).
    Tract,
    /// onnxruntime, loaded from ORT_DYLIB_PATH or the project's .venv.
    Ort,
}

impl From<BackendArg> for BackendKind {
    fn from(b: BackendArg) -> Self {
        match b {
            BackendArg::Tract => BackendKind::Tract,
            BackendArg::Ort => BackendKind::Ort,
        }
    }
}

#[derive(clap::Args, Debug)]
pub struct RenderArgs {
    /// The exported model (`nldf export` writes RUN/model.onnx).
    #[arg(long)]
    pub model: PathBuf,
    /// The speech to animate: a WAV file (any rate, mono or stereo); with --stream, `-`
    /// reads the WAV stream from stdin. With --features it is only the video's sound.
    #[arg(long, required_unless_present = "features")]
    pub audio: Option<PathBuf>,
    /// Ready-made audio feature windows to render from (an `aud.npy`, [N, 16, F], one per
    /// video frame), made by the front end the model was trained on: a model trained on
    /// another front end's features than nldf's (AD-NeRF's DeepSpeech) needs them.
    #[arg(long, conflicts_with = "stream")]
    pub features: Option<PathBuf>,
    /// A transforms json (AD-NeRF layout) whose camera poses to follow, played forwards and
    /// backwards; default: a gentle sway around the model's default pose.
    #[arg(long)]
    pub poses: Option<PathBuf>,
    /// Output folder, created (must be absent or empty).
    #[arg(long, default_value = "render")]
    pub out: PathBuf,
    /// Runtime for the network.
    #[arg(long, value_enum, default_value_t = BackendArg::Tract)]
    pub backend: BackendArg,
    /// The image's longer side in pixels (default: the model's training size).
    #[arg(long)]
    pub size: Option<u32>,
    /// Rays per network call.
    #[arg(long, default_value_t = BackendOptions::default().batch_size)]
    pub batch: usize,
    /// Threads for the network (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Write PNG frames only, no MP4.
    #[arg(long)]
    pub no_video: bool,
    /// The ffmpeg binary that muxes the MP4 (default: `ffmpeg` on the PATH).
    #[arg(long)]
    pub ffmpeg: Option<PathBuf>,
    /// Read the audio as a live WAV stream (`--audio -` for stdin, or a named pipe) and
    /// write each frame as soon as its audio has arrived; frames the renderer cannot keep
    /// up with are skipped so that latency stays bounded. Writes OUT/stream.json with the
    /// latency of every frame.
    #[arg(long)]
    pub stream: bool,
    /// With --stream: render every frame, however far behind the audio that falls.
    #[arg(long, requires = "stream", conflicts_with = "drop_behind")]
    pub no_drop: bool,
    /// With --stream: frames that may wait behind the next one before the renderer skips
    /// to the newest (each adds one frame time, 40 ms at 25 fps, to the worst latency).
    #[arg(long, requires = "stream", default_value_t = nldf_infer::stream::DEFAULT_DROP_BEHIND)]
    pub drop_behind: usize,
    /// While the pose holds still (a --poses track with repeated poses), re-render only the
    /// pixels the audio moves: those whose colour spreads over 8 probe frames of the clip,
    /// grown by 2 pixels; a full frame whenever the pose moves and once a second.
    #[arg(long, conflicts_with = "stream")]
    pub skip_still: bool,
    /// With --skip-still: the colour spread (in 1/255 steps) above which a pixel is
    /// re-rendered (`nldf bench still` measures the trade: lower is closer to full frames,
    /// higher is faster).
    #[arg(
        long,
        default_value_t = nldf_infer::still::DEFAULT_THRESHOLD_STEPS,
        requires = "skip_still"
    )]
    pub skip_threshold: f32,
}

/// The backend options of `--batch` and `--threads` (default: all cores), checked with the
/// flags named.
pub fn backend_options(batch: usize, threads: Option<usize>) -> Result<BackendOptions> {
    let options = BackendOptions {
        batch_size: batch,
        threads: threads.unwrap_or_else(|| BackendOptions::default().threads),
        spin: true,
    };
    let limits = BackendOptions::LIMITS;
    if !(1..=limits.batch_size).contains(&options.batch_size) {
        anyhow::bail!("--batch must be 1 to {}, got {batch}", limits.batch_size);
    }
    if !(1..=limits.threads).contains(&options.threads) {
        anyhow::bail!(
            "--threads must be 1 to {}, got {}",
            limits.threads,
            options.threads
        );
    }
    Ok(options)
}

/// Checks `--size` (the image's longer side) with the flag named.
pub fn check_size(size: Option<u32>) -> Result<()> {
    let max = nldf_infer::frame::MAX_SIDE;
    match size {
        Some(s) if !(1..=max).contains(&s) => {
            anyhow::bail!("--size must be 1 to {max} pixels, got {s}")
        }
        _ => Ok(()),
    }
}

/// Runs `nldf render`.
pub fn run(args: RenderArgs) -> Result<()> {
    let options = backend_options(args.batch, args.threads)?;
    check_size(args.size)?;
    if args.stream {
        return run_stream(args, options);
    }
    let job = VideoJob {
        model: args.model,
        audio: args.audio,
        features: args.features,
        poses: args.poses,
        out: args.out,
        backend: args.backend.into(),
        options,
        size: args.size,
        mp4: !args.no_video,
        ffmpeg: args.ffmpeg,
        skip: args.skip_still.then(|| SkipConfig {
            threshold: args.skip_threshold / 255.0,
            ..SkipConfig::default()
        }),
    };
    let plan = job.plan()?;
    let k = plan.renderer().intrinsics();
    let upsample = plan.renderer().info().upsample;
    let bar = progress_bar(plan.n_frames() as u64, "frames");
    let report = plan.render(|p| bar.set_position(p.done as u64))?;
    bar.finish_and_clear();
    let through = match upsample {
        None => "of the pixels through the network".to_string(),
        Some(up) => format!(
            "as many rays as pixels, the learned upsampler's coarse rays (one per {0} x {0} \
             block)",
            up.factor
        ),
    };
    println!(
        "{} frames of {}x{} at {} fps with {} ({} threads, batch {}): {:.2} frames/s rendering \
         ({:.1} % {through}), {:.2} s writing PNGs",
        report.n_frames,
        k.width,
        k.height,
        report.fps,
        job.backend,
        options.threads,
        options.batch_size,
        report.n_frames as f64 / report.render_seconds.max(1e-9),
        100.0 * report.head_fraction,
        report.write_seconds,
    );
    if job.skip.is_some() {
        println!(
            "skipping still pixels: {} of {} frames rendered in full",
            report.full_frames, report.n_frames
        );
    }
    if report.ffmpeg_missing {
        println!("ffmpeg is not on the PATH: wrote PNG frames only (no MP4)");
    }
    println!("wrote {}:", report.out.display());
    let n = report.files.len();
    for (i, f) in report.files.iter().enumerate() {
        // Every file is listed; long frame lists are folded to their ends.
        if n > 8 && (3..n - 3).contains(&i) {
            if i == 3 {
                println!("  ... {} more frames", n - 6);
            }
            continue;
        }
        println!("  {}", f.display());
    }
    Ok(())
}

/// `nldf render --stream`.
fn run_stream(args: RenderArgs, options: BackendOptions) -> Result<()> {
    let job = StreamJob {
        model: args.model,
        poses: args.poses,
        out: args.out,
        backend: args.backend.into(),
        options,
        size: args.size,
        drop_behind: (!args.no_drop).then_some(args.drop_behind),
    };
    let audio = args
        .audio
        .ok_or_else(|| anyhow::anyhow!("--stream needs --audio (a WAV file, or - for stdin)"))?;
    let stdin = audio.as_os_str() == "-";
    let name = if stdin {
        "stdin".to_string()
    } else {
        audio.display().to_string()
    };
    let source: Box<dyn std::io::Read + Send> = if stdin {
        Box::new(std::io::stdin())
    } else {
        Box::new(
            std::fs::File::open(&audio)
                .map_err(|e| anyhow::anyhow!("{}: cannot open: {e}", audio.display()))?,
        )
    };
    let plan = job.plan()?;
    let k = plan.renderer().intrinsics();
    eprintln!(
        "streaming {name} into {} ({}x{}, {}); waiting for audio",
        job.out.display(),
        k.width,
        k.height,
        job.backend
    );
    let bar = indicatif::ProgressBar::new_spinner();
    let report = plan.run(source, &name, |frame, dropped| {
        bar.set_message(format!(
            "frame {} written, latency {:.0} ms, {dropped} skipped",
            frame.index,
            1e3 * frame.latency_s
        ));
        bar.tick();
    })?;
    bar.finish_and_clear();
    let l = report.latency;
    println!(
        "{} of {} frames rendered from {:.2} s of audio ({} skipped to keep up) with {}; \
         latency from a frame's audio to its PNG: mean {:.0} ms, median {:.0}, p95 {:.0}, \
         max {:.0} (of which {:.0} ms is the features' lookahead)",
        report.rendered(),
        report.n_frames,
        report.audio_seconds,
        report.dropped,
        report.backend,
        l.mean_ms,
        l.p50_ms,
        l.p95_ms,
        l.max_ms,
        1e3 * report.lookahead_s
    );
    println!(
        "wrote {} frames and {}",
        report.rendered(),
        report.out.join(STREAM_REPORT_FILE).display()
    );
    Ok(())
}
