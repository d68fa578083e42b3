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
    }
}

fn teacher_step(args: TeacherStepArgs) -> Result<()> {
    let tmp;
    let data_dir = match &args.data {
        Some(d) => d.clone(),
        None => {
            tmp = tempfile::tempdir().context("creating a temporary folder")?;
            let dir = tmp.path().join("scene");
            eprintln!("generating the synthetic scene in {}", dir.display());
            let cfg = nldf_core::synth::SynthConfig {
                seconds: 4.0,
                ..Default::default()
            };
            nldf_core::synth::generate(&cfg, None, &dir, false, &|| {})?;
            dir
        }
    };
    let data = TrainData::load(&data_dir)?;
    let mut cfg = TeacherRunConfig {
        model: args.preset.config(),
        ..TeacherRunConfig::default()
    };
    cfg.train.batch_rays = args.rays;
    let scratch = tempfile::tempdir().context("creating a temporary folder")?;
    let mut run = TeacherRun::create(scratch.path(), cfg.clone(), &data)?;
    let result = bench_teacher_step(&mut run, &data, 3, args.steps)?;
    let machine = Machine::here();
    let report = serde_json::json!({
        "bench": "teacher-step",
        "machine": machine,
        "settings": {"preset": format!("{:?}", args.preset), "rays": args.rays, "steps": args.steps, "data": data_dir, "config": cfg},
        "result": result,
    });
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let json = args.out.join("teacher_step.json");
    let md = args.out.join("teacher_step.md");
    nldf_core::error::write_json(&json, &report)?;
    nldf_core::error::write_atomic(&md, markdown(&machine, &result).as_bytes())?;
    print!("{}", markdown(&machine, &result));
    println!("wrote {} and {}", json.display(), md.display());
    Ok(())
}

fn markdown(m: &Machine, r: &StepBench) -> String {
    format!(
        "| {} | value |\n|---|---|\n\
         | machine | {} ({} cores, {} rayon threads), commit {} |\n\
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
