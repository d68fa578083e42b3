//! `nldf bench`: throughput benchmarks that write JSON and Markdown beside the machine, the
//! commit and the settings they ran with. The benchmarks are nldf-bench's jobs; this module
//! turns flags into them and prints what they wrote.

use std::path::PathBuf;

use anyhow::Result;
use clap::Subcommand;

use crate::bench_common::{LoadArgs, TimingArgs, print_written};
use nldf_bench::encoding::EncodingJob;
use nldf_bench::step::{StudentStepJob, TeacherStepJob};
use nldf_bench::web::WebBenchJob;

use crate::presets::TeacherPreset;
use crate::progress::EventPrinter;

#[derive(Subcommand, Debug)]
pub enum BenchCommand {
    /// Teacher training steps: rays/s, effective GFLOP/s, cores busy, and candle's matmul
    /// rate at the same shapes.
    TeacherStep(TeacherStepArgs),
    /// Student training steps (88 x 256 by default, 4096 rays plus the pool batch):
    /// rays/s, effective GFLOP/s, cores busy, and the matmul rates at the same shapes.
    StudentStep(StudentStepArgs),
    /// Rendering an exported model: ort whole frames against bare onnxruntime, tract
    /// against ort, and frame time against the share of pixels the head covers.
    Render(crate::bench_model_cmd::RenderBenchArgs),
    /// `nldf render --stream` fed a WAV at real-time speed: the latency from each frame's
    /// audio to its PNG.
    Stream(crate::bench_model_cmd::StreamBenchArgs),
    /// `nldf render --skip-still`: frames re-rendering only the pixels the audio moves,
    /// against full renders, on a still pose, a pose held 2 s at a time and a moving pose:
    /// time per frame and error against the full frames.
    Still(crate::bench_model_cmd::StillBenchArgs),
    /// Run time against error: the teacher and every student of a run, exported in f32,
    /// f16 and int8, in onnxruntime and tract, scored on the held-out splits and timed per
    /// whole frame side by side; a table, JSON and a plot with the Pareto front.
    Frontier(crate::frontier_cmd::FrontierArgs),
    /// The frontier's rows for a run with a learned upsampler (`nldf train upsampler`), at
    /// the run's size: the student on every pixel (native rays), on the coarse grid
    /// upscaled bilinearly, and the upsampled frame graph, in f32 and f16, with the teacher;
    /// scored on the held-out splits (head PSNR and SSIM) and timed per whole frame.
    Upsampler(UpsamplerBenchArgs),
    /// Frame graphs (`nldf export --frame`) in headless Chromium with onnxruntime-web
    /// (WASM, SIMD, threads; web/bench.mjs) beside native onnxruntime and tract, in one
    /// run: frames per second of each, full frames and skipping still pixels (the page's,
    /// and with --ray-model nldf's `--skip-still` in onnxruntime).
    Web(WebBenchArgs),
    /// The positional encoding's sines and cosines three ways (direct f32, f32
    /// double-angle climb, nldf's f64 climb): time per value and error against f64.
    Encoding(EncodingBenchArgs),
    /// A dataset prepared from a test video (`nldf synth --video`) scored against the
    /// synthetic scene it shows, after the one similarity no method can observe: camera
    /// rotations and positions, head-mask IoU, the background's PSNR where the person never
    /// is, and how much of the true mouth the landmarks' lips cover; a table with each
    /// bar, and JSON. Exits non-zero when a bar fails.
    Prepare(PrepareBenchArgs),
    /// Each teacher of the recipe (`mlp`, `grid`) trained on one dataset for the same
    /// training seconds, one after the other: head PSNR on the validation frames against
    /// training seconds, one curve per teacher on one plot, and JSON with the machine.
    Teachers(TeachersBenchArgs),
}

#[derive(clap::Args, Debug)]
pub struct TeachersBenchArgs {
    /// Dataset folder (AD-NeRF's layout).
    #[arg(long)]
    pub data: PathBuf,
    /// Output folder: OUT/<teacher> (each run), OUT/curves.json, OUT/curves.png.
    #[arg(long)]
    pub out: PathBuf,
    /// Training minutes of each teacher (its learning rate held for 60 % of them, then
    /// tenfold down by the clock).
    #[arg(long, default_value_t = 20.0)]
    pub minutes: f64,
    /// Seconds between two measurements.
    #[arg(long, default_value_t = 60.0)]
    pub every: f64,
    /// Validation frames each measurement renders.
    #[arg(long, default_value_t = 4)]
    pub frames: usize,
    /// The teachers, in order (repeat the flag) [default: mlp, then grid].
    #[arg(long, value_enum)]
    pub teacher: Vec<crate::presets::TeacherRecipe>,
}

#[derive(clap::Args, Debug)]
pub struct PrepareBenchArgs {
    /// The synthetic scene (`nldf synth --video`'s dataset): the truth.
    #[arg(long)]
    pub truth: PathBuf,
    /// The dataset prepared from its video (AD-NeRF's layout).
    #[arg(long)]
    pub prepared: PathBuf,
    /// Write the scores, the bars and the verdicts here as JSON.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Also carry the scene's held-out splits (novel, voice, sweep) into the prepared
    /// dataset, their cameras mapped into its world, so that `nldf train --data PREPARED`
    /// scores them as it does on the scene (needs a dataset prepared with the scene's
    /// --focal).
    #[arg(long)]
    pub carry_held_out: bool,
    /// How a held-out camera enters the prepared world: `nearest-frame` moves the prepared
    /// camera of the recorded frame nearest it as the true camera moved from that frame's,
    /// lengths scaled by that frame's own distance to the head (a `voice` frame gets the
    /// prepared pose of the frame it repeats); `similarity` maps it by the one similarity
    /// fitted to the whole recording.
    #[arg(long, value_enum, default_value_t = CarryBy::NearestFrame, requires = "carry_held_out")]
    pub carry_by: CarryBy,
}

/// `--carry-by`'s values.
#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum CarryBy {
    NearestFrame,
    Similarity,
}

impl From<CarryBy> for nldf_prepare::held_out::Carry {
    fn from(c: CarryBy) -> Self {
        match c {
            CarryBy::NearestFrame => Self::NearestFrame,
            CarryBy::Similarity => Self::Similarity,
        }
    }
}

#[derive(clap::Args, Debug)]
pub struct UpsamplerBenchArgs {
    /// Run folder with the teacher, the student and the upsampler.
    #[arg(long)]
    pub run: PathBuf,
    /// The data the run was trained on.
    #[arg(long)]
    pub data: PathBuf,
    /// The upsampler's folder in the run.
    #[arg(long, default_value = "upsampler")]
    pub upsampler: String,
    /// At most this many frames of each split, spread evenly over each kind of view.
    #[arg(long)]
    pub frames: Option<usize>,
    /// Splits to score (repeat the flag) [default: val, novel, voice].
    #[arg(long = "split", value_enum)]
    pub splits: Vec<crate::eval_cmd::SplitArg>,
    /// Leave the teacher out (seconds a frame at 512).
    #[arg(long)]
    pub no_teacher: bool,
    /// Rays per network call of the ray graphs.
    #[arg(long, default_value_t = 4096)]
    pub batch: usize,
    /// The student's products kept in f32 in the int8 ray graph, comma-separated (as
    /// `nldf export --int8-f32`).
    #[arg(long, value_delimiter = ',')]
    pub int8_f32: Vec<String>,
    /// Output folder (default RUN/bench_upsampler).
    #[arg(long)]
    pub out: Option<PathBuf>,
    #[command(flatten)]
    pub load: LoadArgs,
}

fn upsampler(args: UpsamplerBenchArgs) -> Result<()> {
    use nldf_bench::frontier::upsampler_bench::{UpsamplerBench, default_out};
    use nldf_core::dataset::Split;
    let splits: Vec<Split> = if args.splits.is_empty() {
        vec![Split::Val, Split::Novel, Split::Voice]
    } else {
        args.splits.iter().map(|&s| s.into()).collect()
    };
    let job = UpsamplerBench {
        out: args.out.clone().unwrap_or_else(|| default_out(&args.run)),
        run: args.run,
        data: args.data,
        upsampler: args.upsampler,
        frames: args.frames,
        splits,
        teacher: !args.no_teacher,
        batch: args.batch,
        int8_f32: args.int8_f32,
        load: args.load.gate(),
    };
    let mut printer = EventPrinter::default();
    let mut show = |e: &nldf_train::job::JobEvent| printer.show(e);
    let (_, written) = job.run(&mut show)?;
    print_written(&written);
    Ok(())
}

#[derive(clap::Args, Debug)]
pub struct WebBenchArgs {
    /// Frame graphs to time (repeat the flag), e.g. one student's fp32, fp16 and int8.
    #[arg(long = "model", required = true)]
    pub models: Vec<PathBuf>,
    /// The same students' ray graphs (`nldf export`), one per --model in the same order,
    /// timed in onnxruntime skipping still pixels as `nldf render --skip-still` does.
    #[arg(long = "ray-model")]
    pub ray_models: Vec<PathBuf>,
    /// Timed frames per model, runtime and round.
    #[arg(long, default_value_t = 60)]
    pub frames: usize,
    /// Threads of every runtime, the browser's WASM threads too.
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// The page's folder, whose bench.mjs times the browser (needs scripts/web_env.sh).
    #[arg(long, default_value = "web")]
    pub web: PathBuf,
    /// Time the native runtimes only.
    #[arg(long)]
    pub no_browser: bool,
    /// The speech every frame's audio comes from (a WAV, e.g. a dataset's aud.wav)
    /// [default: the synthetic scene's hidden voice, seed 0's `voice` split speaker].
    #[arg(long)]
    pub audio: Option<PathBuf>,
    /// Folder for web.json and web.md.
    #[arg(long, default_value = "runs/bench")]
    pub out: PathBuf,
    #[command(flatten)]
    pub timing: TimingArgs,
}

#[derive(clap::Args, Debug)]
pub struct EncodingBenchArgs {
    /// Frequencies L.
    #[arg(long, default_value_t = 10)]
    pub freqs: usize,
    /// The scene's coordinate range |x| for the first error column.
    #[arg(long, default_value_t = 2.0)]
    pub range: f32,
    /// Timed repetitions (the median is reported).
    #[arg(long, default_value_t = 15)]
    pub reps: usize,
    /// Folder for encoding.json and encoding.md.
    #[arg(long, default_value = "runs/bench")]
    pub out: PathBuf,
    #[command(flatten)]
    pub load: LoadArgs,
}

#[derive(clap::Args, Debug)]
pub struct StudentStepArgs {
    /// Dataset to draw batches from (default: the synthetic scene in a temporary folder).
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Student depth.
    #[arg(long, value_enum, default_value_t = crate::presets::StudentPreset::D88)]
    pub depth: crate::presets::StudentPreset,
    /// Rays per step (the pool adds hard_ratio x this).
    #[arg(long, default_value_t = 4096)]
    pub rays: usize,
    /// Timed steps per round (after 2 untimed ones before the first).
    #[arg(long, default_value_t = 10)]
    pub steps: usize,
    /// Folder for student_step.json and student_step.md.
    #[arg(long, default_value = "runs/bench")]
    pub out: PathBuf,
    #[command(flatten)]
    pub timing: TimingArgs,
}

#[derive(clap::Args, Debug)]
pub struct TeacherStepArgs {
    /// Dataset to draw batches from (default: the synthetic scene, generated into a
    /// temporary folder).
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Network preset.
    #[arg(long, value_enum, default_value_t = TeacherPreset::Small)]
    pub preset: TeacherPreset,
    /// Rays per step.
    #[arg(long, default_value_t = 1024)]
    pub rays: usize,
    /// Timed steps per round (after 3 untimed ones before the first).
    #[arg(long, default_value_t = 20)]
    pub steps: usize,
    /// Folder for teacher_step.json and teacher_step.md.
    #[arg(long, default_value = "runs/bench")]
    pub out: PathBuf,
    #[command(flatten)]
    pub timing: TimingArgs,
}

/// Runs a `nldf bench` subcommand.
pub fn run(cmd: BenchCommand) -> Result<()> {
    match cmd {
        BenchCommand::TeacherStep(args) => teacher_step(args),
        BenchCommand::StudentStep(args) => student_step(args),
        BenchCommand::Render(args) => crate::bench_model_cmd::render(args),
        BenchCommand::Stream(args) => crate::bench_model_cmd::stream(args),
        BenchCommand::Still(args) => crate::bench_model_cmd::still(args),
        BenchCommand::Encoding(args) => encoding(args),
        BenchCommand::Web(args) => web(args),
        BenchCommand::Frontier(args) => crate::frontier_cmd::run(args),
        BenchCommand::Upsampler(args) => upsampler(args),
        BenchCommand::Prepare(args) => prepare(args),
        BenchCommand::Teachers(args) => teachers(args),
    }
}

fn teachers(args: TeachersBenchArgs) -> Result<()> {
    use crate::presets::TeacherRecipe;
    let recipes = if args.teacher.is_empty() {
        vec![TeacherRecipe::Mlp, TeacherRecipe::Grid]
    } else {
        args.teacher.clone()
    };
    let job = nldf_train::job::curves::CurveJob {
        data: args.data.clone(),
        out: args.out.clone(),
        teachers: recipes.iter().map(|r| r.kind()).collect(),
        seconds: args.minutes * 60.0,
        every_s: args.every,
        frames: args.frames,
    };
    let stop = crate::progress::stop_flag();
    let mut printer = EventPrinter::default();
    let report = job.run(&stop, &mut |e| printer.show(e))?;
    println!("| teacher | seconds | steps | head PSNR (dB) | mouth PSNR (dB) |");
    println!("|---|---|---|---|---|");
    for curve in &report.curves {
        if let Some(p) = curve.points.last() {
            let show = |v: Option<f64>| v.map_or("-".into(), |v| format!("{v:.2}"));
            println!(
                "| {} | {:.1} | {} | {} | {} |",
                curve.teacher,
                p.seconds,
                p.step,
                show(p.head_psnr),
                show(p.mouth_psnr)
            );
        }
    }
    println!(
        "machine: {}, {} threads, commit {}",
        report.machine.cpu, report.machine.rayon_threads, report.machine.commit
    );
    Ok(())
}

fn prepare(args: PrepareBenchArgs) -> Result<()> {
    let scores = nldf_prepare::check::score_prepared(&args.truth, &args.prepared)?;
    let report = scores.report(&args.truth, &args.prepared);
    print!("{}", prepare_table(&report));
    if let Some(out) = &args.out {
        nldf_core::files::write_json(out, &report)?;
        println!("wrote {}", out.display());
    }
    if args.carry_held_out {
        let carried = nldf_prepare::held_out::carry_held_out(
            &args.truth,
            &args.prepared,
            args.carry_by.into(),
        )?;
        let names: Vec<&str> = carried.iter().map(|s| s.name()).collect();
        println!(
            "carried the held-out splits {} into {}",
            names.join(", "),
            args.prepared.display()
        );
    }
    let failed: Vec<&str> = report
        .checks
        .iter()
        .filter(|c| !c.pass)
        .map(|c| c.metric.as_str())
        .collect();
    if !failed.is_empty() {
        anyhow::bail!(
            "{} of {} bars failed: {}",
            failed.len(),
            report.checks.len(),
            failed.join("; ")
        );
    }
    Ok(())
}

/// `nldf bench prepare`'s Markdown: a table of the bars, then the counts and the numbers
/// without a bar.
fn prepare_table(report: &nldf_prepare::check::ScoreReport) -> String {
    let mut s = String::from("| metric | value | bar | |\n|---|---:|---|---|\n");
    for c in &report.checks {
        let verdict = if c.pass { "pass" } else { "FAIL" };
        let value = format!("{:.4} {}", c.value, c.unit);
        let bar = format!("{} {}", c.bar, c.unit);
        s += &format!(
            "| {} | {} | {} | {verdict} |\n",
            c.metric,
            value.trim_end(),
            bar.trim_end()
        );
    }
    let r = &report.scores;
    let p = &r.poses;
    s += &format!(
        "\n{} of the truth's {} frames compared ({} missing, {} extra); camera position error \
         mean {:.4} %; head IoU worst {:.4} (frame {}); background scored on {} pixels; lips \
         polygon {:.1} % on the mouth over {} frames; focal ratio {:.4}; the similarity: \
         scale {:.6}, rotation {:.3} deg\n",
        r.frames_compared,
        r.frames_truth,
        r.frames_missing,
        r.frames_extra,
        100.0 * p.position_mean,
        r.head_iou_worst,
        r.head_iou_worst_img_id,
        r.bc_pixels,
        100.0 * r.lips_precision,
        r.mouth_frames,
        r.focal_ratio,
        p.scale,
        p.rotation_deg
    );
    s
}

fn web(args: WebBenchArgs) -> Result<()> {
    if args.frames == 0 || args.threads == 0 {
        anyhow::bail!("--frames and --threads must be positive");
    }
    if !(args.ray_models.is_empty() || args.ray_models.len() == args.models.len()) {
        anyhow::bail!(
            "{} --ray-model for {} --model: give one per --model, in the same order, or none",
            args.ray_models.len(),
            args.models.len()
        );
    }
    let job = WebBenchJob {
        models: args.models,
        ray_models: args.ray_models,
        frames: args.frames,
        threads: args.threads,
        web: (!args.no_browser).then_some(args.web),
        pairs: args.timing.pairs,
        load: args.timing.load.gate(),
        audio: args.audio,
    };
    let report = job.run(&mut |note| eprintln!("{note}"))?;
    print_written(&report.write(&args.out)?);
    Ok(())
}

fn encoding(args: EncodingBenchArgs) -> Result<()> {
    if !(1..=16).contains(&args.freqs) {
        anyhow::bail!("--freqs must be 1 to 16, got {}", args.freqs);
    }
    if !(args.range.is_finite() && args.range > 0.0) {
        anyhow::bail!("--range must be positive, got {}", args.range);
    }
    let job = EncodingJob {
        freqs: args.freqs,
        range: args.range,
        reps: args.reps,
        load: args.load.gate(),
    };
    print_written(&job.run()?.write(&args.out)?);
    Ok(())
}

fn student_step(args: StudentStepArgs) -> Result<()> {
    let job = StudentStepJob {
        data: args.data,
        depth: format!("{:?}", args.depth),
        model: args.depth.config(),
        rays: args.rays,
        steps: args.steps,
        pairs: args.timing.pairs,
        load: args.timing.load.gate(),
    };
    let mut printer = EventPrinter::default();
    let report = job.run(&mut |e| printer.show(e))?;
    print_written(&report.write(&args.out)?);
    Ok(())
}

fn teacher_step(args: TeacherStepArgs) -> Result<()> {
    let job = TeacherStepJob {
        data: args.data,
        preset: format!("{:?}", args.preset),
        model: args.preset.config(),
        rays: args.rays,
        steps: args.steps,
        pairs: args.timing.pairs,
        load: args.timing.load.gate(),
    };
    let mut printer = EventPrinter::default();
    let report = job.run(&mut |e| printer.show(e))?;
    print_written(&report.write(&args.out)?);
    Ok(())
}
