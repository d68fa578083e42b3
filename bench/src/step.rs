//! Training-step benchmarks (`nldf bench teacher-step`, `student-step`): a run created in a
//! scratch folder takes a few untimed steps, then timed ones; the report gives rays/s, the
//! effective FLOP rate, the cores busy and the matmul rates at the same shapes.

use std::path::{Path, PathBuf};

use nldf_train::bench::{Machine, StepBench, bench_student_step, bench_teacher_step};
use nldf_train::config::{StudentRunConfig, TeacherConfig, TeacherRunConfig};
use nldf_train::data::TrainData;
use nldf_train::job::{JobEvent, OnEvent};
use nldf_train::student::StudentConfig;
use nldf_train::student_trainer::StudentRun;
use nldf_train::teacher_trainer::TeacherRun;
use serde::Serialize;

use crate::error::{Result, temp_dir};
use crate::report::{Written, machine_cell, write_bench_files};

/// Teacher training steps on `data` (default: the synthetic scene).
#[derive(Debug, Clone)]
pub struct TeacherStepJob {
    /// Dataset to draw batches from; `None` generates the synthetic scene into a temporary
    /// folder.
    pub data: Option<PathBuf>,
    /// The preset's name, for the report.
    pub preset: String,
    /// The network.
    pub model: TeacherConfig,
    /// Rays per step.
    pub rays: usize,
    /// Timed steps (after 3 untimed ones).
    pub steps: usize,
}

/// Student training steps on `data` (default: the synthetic scene), pixels only.
#[derive(Debug, Clone)]
pub struct StudentStepJob {
    /// Dataset to draw batches from; `None` generates the synthetic scene into a temporary
    /// folder.
    pub data: Option<PathBuf>,
    /// The depth preset's name, for the report.
    pub depth: String,
    /// The network.
    pub model: StudentConfig,
    /// Rays per step (the pool adds `hard_ratio` x this).
    pub rays: usize,
    /// Timed steps (after 2 untimed ones).
    pub steps: usize,
}

/// A training-step benchmark's settings, as its JSON records them.
#[derive(Debug, Clone, Serialize)]
pub struct StepSettings<C> {
    /// The teacher's preset (teacher steps only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub preset: Option<String>,
    /// The student's depth preset (student steps only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub depth: Option<String>,
    pub rays: usize,
    pub steps: usize,
    pub data: PathBuf,
    /// The run's whole configuration.
    pub config: C,
}

/// A training-step benchmark's report: `teacher_step.json` or `student_step.json`.
#[derive(Debug, Clone, Serialize)]
pub struct StepReport<C> {
    /// `teacher-step` or `student-step`.
    pub bench: &'static str,
    pub machine: Machine,
    pub settings: StepSettings<C>,
    pub result: StepBench,
}

impl TeacherStepJob {
    /// Creates a teacher run in a scratch folder and times its steps.
    pub fn run(&self, on_event: OnEvent) -> Result<StepReport<TeacherRunConfig>> {
        let mut tmp = None;
        let data_dir = bench_data(&self.data, &mut tmp, on_event)?;
        let data = TrainData::load(&data_dir)?;
        let mut cfg = TeacherRunConfig {
            model: self.model.clone(),
            ..TeacherRunConfig::default()
        };
        cfg.train.batch_rays = self.rays;
        let scratch = temp_dir()?;
        let mut run = TeacherRun::create(scratch.path(), cfg.clone(), &data)?;
        let result = bench_teacher_step(&mut run, &data, 3, self.steps)?;
        Ok(StepReport {
            bench: "teacher-step",
            machine: Machine::here(),
            settings: StepSettings {
                preset: Some(self.preset.clone()),
                depth: None,
                rays: self.rays,
                steps: self.steps,
                data: data_dir,
                config: cfg,
            },
            result,
        })
    }
}

impl StudentStepJob {
    /// Creates a student run in a scratch folder and times its steps.
    pub fn run(&self, on_event: OnEvent) -> Result<StepReport<StudentRunConfig>> {
        let mut tmp = None;
        let data_dir = bench_data(&self.data, &mut tmp, on_event)?;
        let data = TrainData::load(&data_dir)?;
        let mut cfg = StudentRunConfig {
            model: self.model.clone(),
            ..StudentRunConfig::default()
        };
        cfg.train.batch_rays = self.rays;
        // No teacher here: pixels only (the segment loss costs a few element-wise ops).
        cfg.train.distill = false;
        let scratch = temp_dir()?;
        let mut run = StudentRun::create(scratch.path(), cfg.clone(), &data, None)?;
        run.prepare(&data, None, &mut |_, _| {})?;
        let result = bench_student_step(&mut run, &data, 2, self.steps)?;
        Ok(StepReport {
            bench: "student-step",
            machine: Machine::here(),
            settings: StepSettings {
                preset: None,
                depth: Some(self.depth.clone()),
                rays: self.rays,
                steps: self.steps,
                data: data_dir,
                config: cfg,
            },
            result,
        })
    }
}

impl<C: Serialize> StepReport<C> {
    /// Writes `{bench}.json` and `{bench}.md` (dashes as underscores) into `out`.
    pub fn write(&self, out: &Path) -> Result<Written> {
        write_bench_files(
            out,
            &self.bench.replace('-', "_"),
            self,
            markdown(&self.machine, &self.result),
        )
    }
}

/// The dataset at `data`, or the synthetic scene generated into `tmp`.
fn bench_data(
    data: &Option<PathBuf>,
    tmp: &mut Option<tempfile::TempDir>,
    on_event: OnEvent,
) -> Result<PathBuf> {
    if let Some(d) = data {
        return Ok(d.clone());
    }
    let dir = temp_dir()?;
    let scene = dir.path().join("scene");
    on_event(&JobEvent::Note(format!(
        "generating the synthetic scene in {}",
        scene.display()
    )));
    let cfg = nldf_core::synth::SynthConfig {
        seconds: 4.0,
        ..Default::default()
    };
    nldf_core::synth::generate(&cfg, None, &scene, false, &|| {})?;
    *tmp = Some(dir);
    Ok(scene)
}

/// The report's table: one row per figure.
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
