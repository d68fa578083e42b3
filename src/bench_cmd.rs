//! `nldf bench`: throughput benchmarks that write JSON and Markdown beside the machine, the
//! commit and the settings they ran with.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Subcommand;
use nldf_train::bench::{Machine, StepBench, bench_teacher_step};
use nldf_train::config::TeacherRunConfig;
use nldf_train::data::TrainData;
use nldf_train::teacher_trainer::TeacherRun;

use nldf_infer::backend::BackendOptions;

use crate::train_cmd::TeacherPreset;

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
    Render(RenderBenchArgs),
    /// `nldf render --stream` fed a WAV at real-time speed: the latency from each frame's
    /// audio to its PNG.
    Stream(StreamBenchArgs),
    /// `nldf render --skip-still`: frames re-rendering only the pixels the audio moves,
    /// against full renders, on a still pose, a pose held 2 s at a time and a moving pose:
    /// time per frame and error against the full frames.
    Still(StillBenchArgs),
    /// Run time against error: the teacher and every student of a run, exported in f32,
    /// f16 and int8, in onnxruntime and tract, scored on the held-out splits and timed per
    /// whole frame side by side; a table, JSON and a plot with the Pareto front.
    Frontier(crate::frontier_cmd::FrontierArgs),
    /// The positional encoding's sines and cosines three ways (direct f32, f32
    /// double-angle climb, nldf's f64 climb): time per value and error against f64.
    Encoding(EncodingBenchArgs),
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
}

#[derive(clap::Args, Debug)]
pub struct RenderBenchArgs {
    /// The exported model (`nldf export`).
    #[arg(long)]
    pub model: PathBuf,
    /// Timed frames per measurement (the median is reported).
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
}

#[derive(clap::Args, Debug)]
pub struct StudentStepArgs {
    /// Dataset to draw batches from (default: the synthetic scene in a temporary folder).
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Student depth.
    #[arg(long, value_enum, default_value_t = crate::train_cmd::StudentDepth::D88)]
    pub depth: crate::train_cmd::StudentDepth,
    /// Rays per step (the pool adds hard_ratio x this).
    #[arg(long, default_value_t = 4096)]
    pub rays: usize,
    /// Timed steps (after 2 untimed ones).
    #[arg(long, default_value_t = 10)]
    pub steps: usize,
    /// Folder for student_step.json and student_step.md.
    #[arg(long, default_value = "runs/bench")]
    pub out: PathBuf,
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
    /// Timed steps (after 3 untimed ones).
    #[arg(long, default_value_t = 20)]
    pub steps: usize,
    /// Folder for teacher_step.json and teacher_step.md.
    #[arg(long, default_value = "runs/bench")]
    pub out: PathBuf,
}

/// Runs a `nldf bench` subcommand.
pub fn run(cmd: BenchCommand) -> Result<()> {
    match cmd {
        BenchCommand::TeacherStep(args) => teacher_step(args),
        BenchCommand::StudentStep(args) => student_step(args),
        BenchCommand::Render(args) => render(args),
        BenchCommand::Stream(args) => stream(args),
        BenchCommand::Still(args) => still(args),
        BenchCommand::Encoding(args) => encoding(args),
        BenchCommand::Frontier(args) => crate::frontier_cmd::run(args),
    }
}

fn encoding(args: EncodingBenchArgs) -> Result<()> {
    if !(1..=16).contains(&args.freqs) {
        anyhow::bail!("--freqs must be 1 to 16, got {}", args.freqs);
    }
    if !(args.range.is_finite() && args.range > 0.0) {
        anyhow::bail!("--range must be positive, got {}", args.range);
    }
    let machine = Machine::here();
    let result = nldf_train::bench::bench_encoding(args.freqs, args.range, args.reps);
    let mut md = format!(
        "Positional encoding, L = {}, {} values per call (a beam), one thread; error is the \
         largest difference from the exact sin(2^l x), cos(2^l x) in f64.\n\n\
         Machine: {}\n\n\
         | variant | ns per value | max error, abs(x) <= {} | max error, abs(x) <= 1e4 |\n\
         |---|---|---|---|\n",
        result.n_freqs,
        result.values_per_call,
        machine_cell(&machine),
        result.scene_range
    );
    for v in &result.variants {
        md.push_str(&format!(
            "| {} | {:.1} | {:.2e} | {:.2e} |\n",
            v.name, v.ns_per_value, v.max_error_scene, v.max_error_clamp
        ));
    }
    let report = serde_json::json!({
        "bench": "encoding",
        "machine": machine,
        "settings": {"freqs": args.freqs, "range": args.range, "reps": args.reps},
        "result": result,
    });
    write_bench_files(&args.out, "encoding", &report, &md)
}

/// The dataset at `data`, or the synthetic scene generated into `tmp`.
fn bench_data(data: &Option<PathBuf>, tmp: &mut Option<tempfile::TempDir>) -> Result<PathBuf> {
    if let Some(d) = data {
        return Ok(d.clone());
    }
    let dir = tempfile::tempdir().context("creating a temporary folder")?;
    let scene = dir.path().join("scene");
    eprintln!("generating the synthetic scene in {}", scene.display());
    let cfg = nldf_core::synth::SynthConfig {
        seconds: 4.0,
        ..Default::default()
    };
    nldf_core::synth::generate(&cfg, None, &scene, false, &|| {})?;
    *tmp = Some(dir);
    Ok(scene)
}

/// Writes a benchmark's JSON and Markdown into `out` and prints the Markdown.
fn write_report(
    out: &std::path::Path,
    name: &str,
    settings: serde_json::Value,
    machine: &Machine,
    result: &StepBench,
) -> Result<()> {
    let report = serde_json::json!({
        "bench": name,
        "machine": machine,
        "settings": settings,
        "result": result,
    });
    write_bench_files(
        out,
        &name.replace('-', "_"),
        &report,
        &markdown(machine, result),
    )
}

fn student_step(args: StudentStepArgs) -> Result<()> {
    use nldf_train::config::StudentRunConfig;
    use nldf_train::student_trainer::StudentRun;
    let mut tmp = None;
    let data_dir = bench_data(&args.data, &mut tmp)?;
    let data = TrainData::load(&data_dir)?;
    let mut cfg = StudentRunConfig {
        model: args.depth.config(),
        ..StudentRunConfig::default()
    };
    cfg.train.batch_rays = args.rays;
    // No teacher here: pixels only (the segment loss costs a few element-wise ops).
    cfg.train.distill = false;
    let scratch = tempfile::tempdir().context("creating a temporary folder")?;
    let mut run = StudentRun::create(scratch.path(), cfg.clone(), &data, None)?;
    run.prepare(&data, None, &mut |_, _| {})?;
    let result = nldf_train::bench::bench_student_step(&mut run, &data, 2, args.steps)?;
    let settings = serde_json::json!({"depth": format!("{:?}", args.depth), "rays": args.rays, "steps": args.steps, "data": data_dir, "config": cfg});
    write_report(
        &args.out,
        "student-step",
        settings,
        &Machine::here(),
        &result,
    )
}

fn teacher_step(args: TeacherStepArgs) -> Result<()> {
    let mut tmp = None;
    let data_dir = bench_data(&args.data, &mut tmp)?;
    let data = TrainData::load(&data_dir)?;
    let mut cfg = TeacherRunConfig {
        model: args.preset.config(),
        ..TeacherRunConfig::default()
    };
    cfg.train.batch_rays = args.rays;
    let scratch = tempfile::tempdir().context("creating a temporary folder")?;
    let mut run = TeacherRun::create(scratch.path(), cfg.clone(), &data)?;
    let result = bench_teacher_step(&mut run, &data, 3, args.steps)?;
    let settings = serde_json::json!({"preset": format!("{:?}", args.preset), "rays": args.rays, "steps": args.steps, "data": data_dir, "config": cfg});
    write_report(
        &args.out,
        "teacher-step",
        settings,
        &Machine::here(),
        &result,
    )
}

fn markdown(m: &Machine, r: &StepBench) -> String {
    format!(
        "| {} | value |\n|---|---|\n\
         | machine | {}, {} rayon threads |\n\
         | batch | {} rays, {:.0} hit the head's bounds, {} samples each{} |\n\
         | step time | {:.3} s |\n\
         | throughput | {:.0} rays/s |\n\
         | effective rate (3 x forward FLOPs) | {:.1} GFLOP/s |\n\
         | cores busy | {:.2} |\n\
         | candle matmul at the same shapes | {:.1} GFLOP/s |\n\
         | step rate / matmul rate | {:.1} % |\n\
         | nldf kernel matmul at the same shapes | {:.1} GFLOP/s |\n\
         | machine's f32 register peak (all threads) | {} |\n",
        r.model,
        machine_cell(m),
        m.rayon_threads,
        r.batch_rays,
        r.hit_rays,
        r.samples_per_ray,
        if r.coarse_samples_per_ray > 0 {
            format!(
                " (placed by a forward-only pass over {})",
                r.coarse_samples_per_ray
            )
        } else {
            String::new()
        },
        r.seconds_per_step,
        r.rays_per_s,
        r.effective_gflop_s,
        r.cores_busy,
        r.candle_matmul_gflop_s,
        100.0 * r.fraction_of_candle_matmul,
        r.kernel_matmul_gflop_s,
        match (r.register_peak_gflop_s, r.fraction_of_register_peak) {
            (Some(p), Some(f)) => format!("{p:.1} GFLOP/s (step at {:.1} %)", 100.0 * f),
            _ => "not measured (no FMA vectors)".into(),
        }
    )
}

/// The machine as a table cell: CPU, cores, commit and the load when the benchmark began.
fn machine_cell(m: &Machine) -> String {
    format!(
        "{} ({} cores), commit {}, load {} at the start",
        m.cpu,
        m.cores,
        m.commit,
        m.load_average_1m
            .map(|l| format!("{l:.2}"))
            .unwrap_or_else(|| "unknown".into())
    )
}

/// Writes `report` as `out/{stem}.json` and `markdown` as `out/{stem}.md`, and prints the
/// Markdown.
fn write_bench_files(
    out: &std::path::Path,
    stem: &str,
    report: &serde_json::Value,
    markdown: &str,
) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let json = out.join(format!("{stem}.json"));
    let md = out.join(format!("{stem}.md"));
    nldf_core::files::write_json(&json, report)?;
    nldf_core::files::write_atomic(&md, markdown.as_bytes())?;
    print!("{markdown}");
    println!("wrote {} and {}", json.display(), md.display());
    Ok(())
}

fn render(args: RenderBenchArgs) -> Result<()> {
    use nldf_infer::bench::{RenderBenchConfig, bench_render};
    use nldf_train::plot::{Series, palette, plot_xy};
    let machine = Machine::here();
    let model = nldf_export::read_model(&args.model)?;
    let cfg = RenderBenchConfig {
        reps: args.reps,
        options: crate::render_cmd::backend_options(args.batch, args.threads)?,
        ..RenderBenchConfig::default()
    };
    let r = bench_render(&model, &cfg, |what| eprintln!("{what}"))?;
    let ms = |s: f64| 1e3 * s;
    let pct = |f: f64| 100.0 * f;
    let mut md = format!(
        "| render, {} x {} student, {}x{} frames | value |\n|---|---|\n\
         | machine | {} |\n\
         | settings | batch {}, {} threads, median of {} frames after {} untimed |\n\
         | default frame | head covers {:.1} % of the pixels ({} rays) |\n\
         | bare onnxruntime, the same rays | {:.1} ms ({:.0} rays/s) |\n\
         | ort whole frame | {:.1} ms ({:.0} rays/s, {:.2} frames/s) |\n\
         | ort whole frame / bare | {:.1} % of the bare throughput |\n\
         | tract whole frame | {:.1} ms ({:.2} frames/s) |\n\
         | tract / ort | {:.2}x the time |\n\
         | every pixel through the network (ort) | {:.1} ms ({} rays) |\n",
        r.depth,
        r.width,
        r.image_width,
        r.image_height,
        machine_cell(&machine),
        cfg.options.batch_size,
        cfg.options.threads,
        cfg.reps,
        cfg.warmup,
        pct(r.ort_frame.head_fraction),
        r.ort_frame.network_rays,
        ms(r.bare_ort.seconds),
        r.bare_ort.rays_per_s,
        ms(r.ort_frame.seconds),
        r.ort_frame.rays_per_s,
        1.0 / r.ort_frame.seconds,
        pct(r.ort_frame_over_bare),
        ms(r.tract_frame.seconds),
        1.0 / r.tract_frame.seconds,
        r.tract_over_ort,
        ms(r.full_frame.seconds),
        r.full_frame.network_rays,
    );
    for t in &r.coverage {
        md += &format!(
            "| head on {:.1} % of the pixels (focal {:.0} px) | {:.1} ms, {:.1} % of every-pixel time |\n",
            pct(t.head_fraction),
            t.focal,
            ms(t.seconds),
            pct(t.seconds / r.full_frame.seconds)
        );
    }
    if let Some((share, ratio)) = r.at_30_percent {
        md += &format!(
            "| at {:.1} % coverage | {:.1} % of the every-pixel frame time |\n",
            pct(share),
            pct(ratio)
        );
    }
    let mut points: Vec<(f64, f64)> = r
        .coverage
        .iter()
        .chain(std::iter::once(&r.ort_frame))
        .map(|t| (pct(t.head_fraction), ms(t.seconds)))
        .collect();
    points.sort_by(|a, b| a.0.total_cmp(&b.0));
    let full = ms(r.full_frame.seconds);
    let series = [
        Series {
            label: "ort, rays that miss the head skipped".into(),
            color: palette(0),
            points,
            marked: true,
        },
        Series {
            label: "ort, every pixel through the network".into(),
            color: palette(1),
            points: vec![(0.0, full), (100.0, full)],
            marked: false,
        },
        Series {
            label: "proportional to head pixels".into(),
            color: palette(2),
            points: vec![(0.0, 0.0), (100.0, full)],
            marked: false,
        },
    ];
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let png = args.out.join("render.png");
    plot_xy(
        &png,
        &format!(
            "frame time against head coverage ({} x {}, {}x{})",
            r.depth, r.width, r.image_width, r.image_height
        ),
        ("pixels the head covers (%)", "ms per frame"),
        &series,
    )?;
    let report = serde_json::json!({
        "bench": "render",
        "machine": machine,
        "model": args.model,
        "result": r,
    });
    write_bench_files(&args.out, "render", &report, &md)?;
    println!("wrote {}", png.display());
    Ok(())
}

fn stream(args: StreamBenchArgs) -> Result<()> {
    use nldf_infer::stream::{StreamJob, paced_wav_stream};
    let machine = Machine::here();
    if !(args.seconds.is_finite() && args.seconds > 0.0) {
        anyhow::bail!("--seconds must be positive, got {}", args.seconds);
    }
    let wave = nldf_core::audio::read_wav(&args.audio)?;
    let wave = wave.truncated((args.seconds * wave.sample_rate as f64) as usize);
    let frames = tempfile::tempdir().context("creating a temporary folder")?;
    let job = StreamJob {
        model: args.model.clone(),
        poses: None,
        out: frames.path().join("frames"),
        backend: args.backend.into(),
        options: BackendOptions::default(),
        size: args.size,
        drop_behind: Some(args.drop_behind),
    };
    let plan = job.plan()?;
    eprintln!(
        "streaming {:.1} s of {} at real-time speed",
        wave.seconds(),
        args.audio.display()
    );
    let source = paced_wav_stream(
        &wave,
        1.0,
        std::time::Duration::from_millis(args.piece_ms.max(1)),
    )?;
    let report = plan.run(source, "the paced stream", |_, _| {})?;
    let l = report.latency;
    let render_ms: Vec<f64> = report.frames.iter().map(|f| 1e3 * f.render_s).collect();
    let mean_render = render_ms.iter().sum::<f64>() / render_ms.len().max(1) as f64;
    let render = nldf_infer::stream::LatencyStats::of(
        &report.frames.iter().map(|f| f.render_s).collect::<Vec<_>>(),
    );
    let md = format!(
        "| stream, {} | value |\n|---|---|\n\
         | machine | {} |\n\
         | model | {} |\n\
         | input | {:.1} s of {} at real-time speed, {} ms pieces, {}x{} frames |\n\
         | frames | {} of {} rendered, {} skipped to keep up (skipping once more than {} wait) |\n\
         | render time per frame, PNG written | {:.1} ms mean, median {:.1}, p95 {:.1}, max {:.1} |\n\
         | features' lookahead | {:.0} ms |\n\
         | latency, audio to PNG | mean {:.0} ms, median {:.0}, p95 {:.0}, max {:.0} |\n",
        report.backend,
        machine_cell(&machine),
        args.model.display(),
        report.audio_seconds,
        args.audio.display(),
        args.piece_ms,
        report.width,
        report.height,
        report.rendered(),
        report.n_frames,
        report.dropped,
        args.drop_behind,
        mean_render,
        render.p50_ms,
        render.p95_ms,
        render.max_ms,
        1e3 * report.lookahead_s,
        l.mean_ms,
        l.p50_ms,
        l.p95_ms,
        l.max_ms,
    );
    let json = serde_json::json!({
        "bench": "stream",
        "machine": machine,
        "model": args.model,
        "settings": {"audio": args.audio, "seconds": args.seconds, "piece_ms": args.piece_ms, "size": args.size, "drop_behind": args.drop_behind},
        "result": report,
    });
    write_bench_files(&args.out, "stream", &json, &md)
}

fn still(args: StillBenchArgs) -> Result<()> {
    use nldf_core::audio::neighbourhood;
    use nldf_infer::backend::backend_for;
    use nldf_infer::frame::FrameRenderer;
    use nldf_infer::poses::{default_pose, default_track};
    use nldf_infer::still::{SkipConfig, bench_track, probe_frames};
    let machine = Machine::here();
    let mut options = crate::render_cmd::backend_options(args.batch, args.threads)?;
    // The full and the skipping renderer take turns: neither pool may spin beside the other.
    options.spin = false;
    if !(args.seconds.is_finite() && args.seconds > 0.0) {
        anyhow::bail!("--seconds must be positive, got {}", args.seconds);
    }
    if args.thresholds.is_empty() {
        anyhow::bail!("--thresholds needs at least one value");
    }
    let model = nldf_export::read_model(&args.model)?;
    let info = model.info.clone();
    let windows = nldf_infer::audio::windows_from_wav(&info, &args.model, &args.audio)?;
    let frames =
        ((args.seconds * info.spec.fps as f64).round() as usize).clamp(1, windows.n_frames.max(1));
    let att = info.audio.att_frames;
    let configs = args
        .thresholds
        .iter()
        .map(|&t| {
            let c = SkipConfig {
                threshold: t / 255.0,
                ..SkipConfig::default()
            };
            c.validate().map(|_| c)
        })
        .collect::<Result<Vec<_>, _>>()?;
    let config = configs[0];
    let audio = |f: usize| neighbourhood(&windows, f, att);
    let probes: Vec<Vec<f32>> = probe_frames(frames, config.probes)
        .into_iter()
        .map(audio)
        .collect();
    let kind: nldf_infer::BackendKind = args.backend.into();
    let mut full = FrameRenderer::new(backend_for(&model, kind, options)?, None)?;
    let mut skipping = FrameRenderer::new(backend_for(&model, kind, options)?, None)?;
    let moving = default_track(&info, frames);
    let hold = (2.0 * info.spec.fps).round().max(1.0) as usize;
    let tracks = [
        ("still pose", vec![default_pose(&info, 0); frames]),
        (
            "pose held 2 s at a time",
            (0..frames).map(|f| moving[f - f % hold]).collect(),
        ),
        ("moving pose (the default sway)", moving.clone()),
    ];
    // Every threshold on the still and the held tracks; the moving track never skips, so
    // it runs once.
    let mut rows = Vec::new();
    for (i, (label, poses)) in tracks.iter().enumerate() {
        let moving = i == tracks.len() - 1;
        for c in if moving { &configs[..1] } else { &configs[..] } {
            eprintln!(
                "{label}, threshold {}/255: {frames} frames in full and with skipping",
                255.0 * c.threshold
            );
            let mut row = bench_track(
                &mut full,
                &mut skipping,
                label,
                poses,
                &audio,
                *c,
                probes.clone(),
            )?;
            row.label = format!("{label}, threshold {:.0}/255", 255.0 * c.threshold);
            rows.push(row);
        }
    }
    let opt = |v: Option<f64>| v.map_or("identical".into(), |p| format!("{p:.2} dB"));
    let mut md = format!(
        "| skipping still pixels, {} x {} student, {} | value |\n|---|---|\n\
         | machine | {} |\n\
         | settings | {:.1} s of {} ({} frames), {} with {} threads, batch {}; thresholds {:?}/255, margin {} px, {} probes, a full frame every {} still frames |\n",
        info.network.depth,
        info.network.width,
        kind,
        machine_cell(&machine),
        frames as f64 / info.spec.fps as f64,
        args.audio.display(),
        frames,
        kind,
        options.threads,
        options.batch_size,
        args.thresholds,
        config.margin,
        config.probes,
        config.refresh,
    );
    md += "\n| track | full ms/frame (mean, median) | skipping ms/frame (mean, median) | speed-up | network rays | full frames | PSNR vs full | worst frame | max error |\n|---|---|---|---|---|---|---|---|---|\n";
    for r in &rows {
        md += &format!(
            "| {} | {:.1}, {:.1} | {:.1}, {:.1} | {:.2}x | {:.1} % | {} of {} | {} | {} | {:.1}/255 |\n",
            r.label,
            r.full_ms_mean,
            r.full_ms_median,
            r.skip_ms_mean,
            r.skip_ms_median,
            r.speedup,
            100.0 * r.ray_share,
            r.full_frames,
            r.frames,
            opt(r.psnr_vs_full),
            opt(r.worst_frame_psnr),
            255.0 * r.max_abs_error,
        );
    }
    let json = serde_json::json!({
        "bench": "still",
        "machine": machine,
        "model": args.model,
        "settings": {"audio": args.audio, "seconds": args.seconds, "frames": frames, "backend": kind.to_string(), "threads": options.threads, "batch": options.batch_size, "skip": config, "thresholds": args.thresholds},
        "tracks": rows,
    });
    write_bench_files(&args.out, "still", &json, &md)
}
