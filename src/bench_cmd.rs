//! `nldf bench`: throughput benchmarks that write JSON and Markdown beside the machine, the
//! commit and the settings they ran with.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Subcommand;
use nldf_train::bench::{Machine, StepBench, bench_teacher_step};
use nldf_train::config::TeacherRunConfig;
use nldf_train::trainer::{TeacherRun, TrainData};

use crate::train_cmd::TeacherPreset;

#[derive(Subcommand, Debug)]
pub enum BenchCommand {
    /// Teacher training steps: rays/s, effective GFLOP/s, cores busy, and candle's matmul
    /// rate at the same shapes.
    TeacherStep(TeacherStepArgs),
    /// Student training steps (88 x 256 by default, 4096 rays plus the pool batch):
    /// rays/s, effective GFLOP/s, cores busy, and the matmul rates at the same shapes.
    StudentStep(StudentStepArgs),
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
    }
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
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let stem = name.replace('-', "_");
    let json = out.join(format!("{stem}.json"));
    let md = out.join(format!("{stem}.md"));
    nldf_core::error::write_json(&json, &report)?;
    nldf_core::error::write_atomic(&md, markdown(machine, result).as_bytes())?;
    print!("{}", markdown(machine, result));
    println!("wrote {} and {}", json.display(), md.display());
    Ok(())
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
         | machine | {} ({} cores, {} rayon threads), commit {}, load {} at the start |\n\
         | batch | {} rays, {:.0} hit the head's bounds, {} samples each |\n\
         | step time | {:.3} s |\n\
         | throughput | {:.0} rays/s |\n\
         | effective rate (3 x forward FLOPs) | {:.1} GFLOP/s |\n\
         | cores busy | {:.2} |\n\
         | candle matmul at the same shapes | {:.1} GFLOP/s |\n\
         | step rate / matmul rate | {:.1} % |\n\
         | nldf kernel matmul at the same shapes | {:.1} GFLOP/s |\n",
        r.model,
        m.cpu,
        m.cores,
        m.rayon_threads,
        m.commit,
        m.load_average_1m
            .map(|l| format!("{l:.2}"))
            .unwrap_or_else(|| "unknown".into()),
        r.batch_rays,
        r.hit_rays,
        r.samples_per_ray,
        r.seconds_per_step,
        r.rays_per_s,
        r.effective_gflop_s,
        r.cores_busy,
        r.candle_matmul_gflop_s,
        100.0 * r.fraction_of_candle_matmul,
        r.kernel_matmul_gflop_s
    )
}
