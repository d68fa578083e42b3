//! `nldf bench frontier`: run time against error. The job is nldf-bench's
//! [`FrontierJob`]: every way nldf can render a run's held-out frames (the teacher in candle
//! with and without its savings, every student exported in f32, f16 and int8 in onnxruntime
//! and tract) scored and timed side by side, with the Pareto front and the students'
//! speed-up over the teacher at matched PSNR; this module turns flags into the job and
//! prints the report it wrote.

use std::path::PathBuf;

use anyhow::Result;
use nldf_bench::frontier::FrontierJob;
use nldf_infer::BackendOptions;

use crate::progress::EventPrinter;

#[derive(clap::Args, Debug)]
pub struct FrontierArgs {
    /// Run folder: its teacher and every student in it.
    #[arg(long)]
    pub run: PathBuf,
    /// The dataset the run was trained on (its `val` split, and `novel` and `voice` where
    /// `nldf synth` wrote them).
    #[arg(long)]
    pub data: PathBuf,
    /// Output folder [default: RUN/frontier].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// At most this many frames per split, spread evenly over each kind of view.
    #[arg(long)]
    pub frames: Option<usize>,
    /// Frames timed with 1 thread per point.
    #[arg(long, default_value_t = 6)]
    pub one_thread_frames: usize,
    /// Training frames that calibrate the int8 exports.
    #[arg(long, default_value_t = 16)]
    pub calibration_frames: usize,
    /// Rays per network call.
    #[arg(long, default_value_t = BackendOptions::default().batch_size)]
    pub batch: usize,
    /// Frames timed for AD-NeRF's setting (8 x 256, 64 + 128 samples per ray, every pixel
    /// and every sample, seeded weights: its time, not its quality), each rendered in turn
    /// by the points it is set against: the pairs of its speed-ups; 0 leaves it out.
    #[arg(long, default_value_t = nldf_bench::repeats::DEFAULT_PAIRS)]
    pub adnerf_frames: usize,
    /// The same scene at a higher resolution (`nldf synth --seed S --size 256`): the
    /// teacher and every export in onnxruntime render its `val` frames at its size, with
    /// rays at that size and, where it is a multiple of the model's, with rays at the
    /// model's size upscaled bilinearly; scored, timed and tabled apart.
    #[arg(long)]
    pub hires_data: Option<PathBuf>,
    /// Frames each point also renders back to back, as a video renders them, for a second
    /// 2-thread median beside the scoring pass's: in three rounds where every point takes
    /// its turn, each turn one untimed frame and then its share of these.
    #[arg(long, default_value_t = 8)]
    pub timed_frames: usize,
    /// A learned upsampler of the run (its folder, e.g. `upsampler`; repeat the flag): its
    /// upsampled ray graph joins the frontier in fp16 and with int8 products, scored and
    /// timed per whole frame as the students are.
    #[arg(long)]
    pub upsampler: Vec<String>,
    /// The student's products kept in f32 in the upsampled int8 graphs, comma-separated
    /// (as `nldf export --int8-f32`).
    #[arg(long, value_delimiter = ',', requires = "upsampler")]
    pub int8_f32: Vec<String>,
    #[command(flatten)]
    pub load: crate::bench_common::LoadArgs,
}

/// Runs `nldf bench frontier`.
pub fn run(args: FrontierArgs) -> Result<()> {
    let out = args.out.unwrap_or_else(|| args.run.join("frontier"));
    let job = FrontierJob {
        run: args.run,
        data: args.data,
        out,
        frames: args.frames,
        one_thread_frames: args.one_thread_frames,
        calibration_frames: args.calibration_frames,
        batch: args.batch,
        adnerf_frames: args.adnerf_frames,
        hires_data: args.hires_data,
        timed_frames: args.timed_frames,
        upsamplers: args.upsampler,
        int8_f32: args.int8_f32,
        load: args.load.gate(),
    };
    let mut printer = EventPrinter::default();
    let report = job.run(&mut |e| printer.show(e))?;
    let written = report.write(&job.out)?;
    println!("{}", written.markdown);
    println!(
        "wrote {}, {} and {}",
        written.json.display(),
        written.md.display(),
        written
            .plots
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    Ok(())
}
