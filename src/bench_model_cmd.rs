//! `nldf bench render`, `stream` and `still`: benchmarks of an exported model, run by
//! nldf-bench; this module checks the flags, runs the job and prints what it wrote.

use std::path::PathBuf;

use anyhow::Result;
use nldf_bench::render::RenderBenchPlan;
use nldf_bench::still::StillBenchJob;
use nldf_bench::stream::StreamBenchJob;
use nldf_infer::backend::BackendOptions;

use crate::bench_common::print_written;
use crate::progress::EventPrinter;

#[derive(clap::Args, Debug)]
pub struct RenderBenchArgs {
    /// The exported model (`nldf export`).
    #[arg(long)]
    pub model: PathBuf,
    /// Timed frames per measurement and round (the median is reported).
    #[arg(long, default_value_t = 7)]
    pub reps: usize,
    /// Rays per network call.
    #[arg(long, default_value_t = BackendOptions::default().batch_size)]
    pub batch: usize,
    /// Threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Folder for render.json, render.md and render.png.
    #[arg(long, default_value = "runs/bench")]
    pub out: PathBuf,
    #[command(flatten)]
    pub timing: crate::bench_common::TimingArgs,
}

#[derive(clap::Args, Debug)]
pub struct StreamBenchArgs {
    /// The exported model (`nldf export`).
    #[arg(long)]
    pub model: PathBuf,
    /// Speech to stream (its first --seconds are used).
    #[arg(long)]
    pub audio: PathBuf,
    /// Seconds of audio to stream.
    #[arg(long, default_value_t = 10.0)]
    pub seconds: f64,
    /// Runtime for the network.
    #[arg(long, value_enum, default_value_t = crate::render_cmd::BackendArg::Ort)]
    pub backend: crate::render_cmd::BackendArg,
    /// The image's longer side in pixels (default: the model's training size).
    #[arg(long)]
    pub size: Option<u32>,
    /// Audio sent per write, in milliseconds (a microphone's buffer).
    #[arg(long, default_value_t = 20)]
    pub piece_ms: u64,
    /// Frames that may wait behind the next one before the stream skips to the newest.
    #[arg(long, default_value_t = nldf_infer::stream::DEFAULT_DROP_BEHIND)]
    drop_behind: usize,
    /// Folder for stream.json and stream.md (the frames go to a temporary folder).
    #[arg(long, default_value = "runs/bench")]
    pub out: PathBuf,
    #[command(flatten)]
    pub load: crate::bench_common::LoadArgs,
}

#[derive(clap::Args, Debug)]
pub struct StillBenchArgs {
    /// The exported model (`nldf export`).
    #[arg(long)]
    pub model: PathBuf,
    /// Speech to render (its first --seconds are used).
    #[arg(long)]
    pub audio: PathBuf,
    /// Seconds of audio per pose track.
    #[arg(long, default_value_t = 10.0)]
    pub seconds: f64,
    /// Runtime for the network.
    #[arg(long, value_enum, default_value_t = crate::render_cmd::BackendArg::Ort)]
    pub backend: crate::render_cmd::BackendArg,
    /// Colour spreads (in 1/255 steps) above which a pixel is re-rendered, one measurement
    /// each, comma-separated.
    #[arg(long, value_delimiter = ',', default_values_t = [2.0, 6.0, 12.0, 24.0])]
    pub thresholds: Vec<f32>,
    /// Rays per network call.
    #[arg(long, default_value_t = BackendOptions::default().batch_size)]
    pub batch: usize,
    /// Threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Folder for still.json and still.md.
    #[arg(long, default_value = "runs/bench")]
    pub out: PathBuf,
    #[command(flatten)]
    pub timing: crate::bench_common::TimingArgs,
}

/// Runs `nldf bench render`.
pub fn render(args: RenderBenchArgs) -> Result<()> {
    let options = crate::render_cmd::backend_options(args.batch, args.threads)?;
    let plan = RenderBenchPlan::open(&args.model, args.timing.load.gate())?;
    let mut printer = EventPrinter::default();
    let report = plan.run(args.reps, args.timing.pairs, options, &mut |e| {
        printer.show(e)
    })?;
    print_written(&report.write(&args.out)?);
    Ok(())
}

/// Runs `nldf bench stream`.
pub fn stream(args: StreamBenchArgs) -> Result<()> {
    if !(args.seconds.is_finite() && args.seconds > 0.0) {
        anyhow::bail!("--seconds must be positive, got {}", args.seconds);
    }
    let job = StreamBenchJob {
        model: args.model,
        audio: args.audio,
        seconds: args.seconds,
        backend: args.backend.into(),
        size: args.size,
        piece_ms: args.piece_ms,
        drop_behind: args.drop_behind,
        load: args.load.gate(),
    };
    let mut printer = EventPrinter::default();
    let report = job.run(&mut |e| printer.show(e))?;
    print_written(&report.write(&args.out)?);
    Ok(())
}

/// Runs `nldf bench still`.
pub fn still(args: StillBenchArgs) -> Result<()> {
    let options = crate::render_cmd::backend_options(args.batch, args.threads)?;
    if !(args.seconds.is_finite() && args.seconds > 0.0) {
        anyhow::bail!("--seconds must be positive, got {}", args.seconds);
    }
    if args.thresholds.is_empty() {
        anyhow::bail!("--thresholds needs at least one value");
    }
    let job = StillBenchJob {
        model: args.model,
        audio: args.audio,
        seconds: args.seconds,
        backend: args.backend.into(),
        thresholds: args.thresholds,
        options,
        pairs: args.timing.pairs,
        load: args.timing.load.gate(),
    };
    let mut printer = EventPrinter::default();
    let report = job.run(&mut |e| printer.show(e))?;
    print_written(&report.write(&args.out)?);
    Ok(())
}
