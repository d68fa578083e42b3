//! The `nldf` command line: a thin front end over the workspace's libraries.

mod ablate_cmd;
mod bench_cmd;
mod bench_common;
mod bench_model_cmd;
mod demo_cmd;
mod doctor_cmd;
mod eval_cmd;
mod export_cmd;
mod features_cmd;
mod frontier_cmd;
mod lookahead_cmd;
mod prepare_cmd;
mod presets;
mod progress;
mod render_cmd;
mod synth_cmd;
mod train_cmd;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

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
    /// The whole pipeline on the synthetic talking head: scene, teacher, student, ONNX
    /// export, evaluation of both on the held-out frames, and a video of the student
    /// speaking with a voice it never heard; ends with a table of quality and speed.
    Demo(demo_cmd::DemoArgs),
    /// Generate the synthetic talking head as an AD-NeRF dataset (frames, background, audio,
    /// audio features, camera poses, depth, parsing masks and scene.json ground truth), with
    /// the novel, voice and sweep evaluation splits.
    Synth(synth_cmd::SynthArgs),
    /// Turn a video of one person speaking (an MP4 with sound) into a dataset on a CPU:
    /// frames, 16 kHz audio and its features, 68 landmarks, head poses, parsing masks and
    /// the background, in AD-NeRF's layout.
    Prepare(prepare_cmd::PrepareArgs),
    /// Train on a dataset: with `--data DIR --run RUN` the whole recipe of `nldf demo`
    /// (teacher, distilled real-time student, export, scores, video), or one stage: the
    /// teacher NeRF, the light-field student, the learned upsampler.
    Train(train_cmd::TrainArgs),
    /// Make a WAV file's audio features with nldf's front end, as an AD-NeRF `aud.npy` with
    /// its settings in `aud.json` beside it.
    Features(features_cmd::FeaturesArgs),
    /// Render held-out frames (or the novel, voice or sweep split) with a run's teacher and
    /// students and score them (PSNR, SSIM, head and mouth PSNR).
    Eval(eval_cmd::EvalArgs),
    /// Export a run's trained student (with its audio encoder) as one ONNX model.
    Export(export_cmd::ExportArgs),
    /// Render a talking-head video from an exported model and a WAV file (PNG frames, and
    /// an MP4 with the audio when ffmpeg is on the PATH).
    Render(render_cmd::RenderArgs),
    /// The paper's ablations on one dataset: distillation, the beam pool, depth, and a
    /// pixels-only student at the same total wall time; or, with --posed-minutes, students
    /// with and without pseudo views scored beyond the recorded poses.
    Ablate(ablate_cmd::AblateArgs),
    /// Benchmarks: training steps, the positional encoding, frame rendering (tract and
    /// onnxruntime), streaming latency, and the run-time against error frontier of a run's
    /// teacher and students (fp32, fp16, int8), each written as JSON and Markdown.
    #[command(subcommand)]
    Bench(bench_cmd::BenchCommand),
    /// Show what nldf finds on this machine: CPU features and threads, the onnxruntime
    /// library and where it was found, ffmpeg and Python.
    Doctor,
}

/// A command-line mistake as one line: clap's message and its hints (`[possible values:
/// ...]`, `tip: ...`) without the usage block, then where to look.
fn one_line(e: &clap::Error) -> String {
    let text = e.render().to_string();
    let mut parts = Vec::new();
    for line in text.lines().map(str::trim) {
        if line.starts_with("Usage:") {
            break;
        }
        if !line.is_empty() && !line.starts_with("For more information") {
            parts.push(line.trim_start_matches("error: "));
        }
    }
    format!("{} (see --help)", parts.join(" "))
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) if !e.use_stderr() => {
            // --help and --version.
            let _ = e.print();
            return ExitCode::SUCCESS;
        }
        Err(e) => {
            eprintln!("error: {}", one_line(&e));
            return ExitCode::from(2);
        }
    };
    // Training allocates and frees the same large buffers every step: keep them.
    nldf_train::trainers::memory::keep_freed_memory();
    // NLDF_KERNELS forces the training kernels' path (checked before any work starts).
    if let Err(e) =
        nldf_train::kernels::KernelPath::from_env().and_then(nldf_train::kernels::use_path)
    {
        eprintln!("error: {e}");
        return ExitCode::from(2);
    }
    let result = match cli.command {
        Command::Demo(args) => demo_cmd::run(args),
        Command::Synth(args) => synth_cmd::run(args),
        Command::Prepare(args) => prepare_cmd::run(args),
        Command::Train(args) => train_cmd::run(args),
        Command::Features(args) => features_cmd::run(args),
        Command::Eval(args) => eval_cmd::run(args),
        Command::Export(args) => export_cmd::run(args),
        Command::Render(args) => render_cmd::run(args),
        Command::Ablate(args) => ablate_cmd::run(args),
        Command::Bench(cmd) => bench_cmd::run(cmd),
        Command::Doctor => doctor_cmd::run(),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
