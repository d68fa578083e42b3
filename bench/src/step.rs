//! Training-step benchmarks (`nldf bench teacher-step`, `student-step`): a run created in a
//! scratch folder takes a few untimed steps, then timed ones; the report gives rays/s, the
//! effective FLOP rate, the cores busy and the matmul rates at the same shapes. The steps and
//! the matmuls take turns in rounds (steps, matmuls, steps, ...), so that the step's rate
//! against the matmuls' is a ratio over interleaved pairs ([`crate::repeats`]).

use std::path::{Path, PathBuf};

use nldf_core::host::Machine;
use nldf_train::job::{JobEvent, OnEvent};
use nldf_train::networks::student::StudentConfig;
use nldf_train::reports::bench::{StepBench, bench_student_step, bench_teacher_step};
use nldf_train::trainers::config::{StudentRunConfig, TeacherConfig, TeacherRunConfig};
use nldf_train::trainers::data::TrainData;
use nldf_train::trainers::student_trainer::StudentRun;
use nldf_train::trainers::teacher_trainer::TeacherRun;
use serde::Serialize;

use crate::error::{Result, temp_dir};
use crate::load::LoadGate;
use crate::repeats::{Ratio, check_pairs};
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
    /// Timed steps per round (after 3 untimed ones before the first).
    pub steps: usize,
    /// Rounds: each times `steps` steps, then the matmuls at the same shapes.
    pub pairs: usize,
    /// The load limit at the start.
    pub load: LoadGate,
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
    /// Timed steps per round (after 2 untimed ones before the first).
    pub steps: usize,
    /// Rounds: each times `steps` steps, then the matmuls at the same shapes.
    pub pairs: usize,
    /// The load limit at the start.
    pub load: LoadGate,
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
    /// Timed steps per round.
    pub steps: usize,
    /// Rounds of steps and matmuls.
    pub pairs: usize,
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
    /// The middle round by step time (the faster of the two middle ones for an even
    /// count).
    pub result: StepBench,
    /// Every round, in order.
    pub rounds: Vec<StepBench>,
    /// The step's effective rate over candle's matmul rate at the same shapes, per round.
    pub step_over_candle_matmul: Ratio,
    /// The same over nldf's own matmul kernel.
    pub step_over_kernel_matmul: Ratio,
    /// The same over the machine's f32 register peak, where measured.
    pub step_over_register_peak: Option<Ratio>,
}

/// The report of `rounds` (at least one): the middle round by step time and the ratios over
/// them.
fn step_report<C>(
    bench: &'static str,
    machine: Machine,
    settings: StepSettings<C>,
    rounds: Vec<StepBench>,
) -> Result<StepReport<C>> {
    let of =
        |f: &dyn Fn(&StepBench) -> f64| Ratio::of_ratios(&rounds.iter().map(f).collect::<Vec<_>>());
    let step_over_candle_matmul = of(&|r| r.fraction_of_candle_matmul)?;
    let step_over_kernel_matmul = of(&|r| r.effective_gflop_s / r.kernel_matmul_gflop_s)?;
    let step_over_register_peak = if rounds.iter().all(|r| r.fraction_of_register_peak.is_some()) {
        Some(of(&|r| r.fraction_of_register_peak.unwrap_or(f64::NAN))?)
    } else {
        None
    };
    let mut order: Vec<usize> = (0..rounds.len()).collect();
    order.sort_by(|&a, &b| {
        rounds[a]
            .seconds_per_step
            .total_cmp(&rounds[b].seconds_per_step)
    });
    let result = rounds[order[(order.len() - 1) / 2]].clone();
    Ok(StepReport {
        bench,
        machine,
        settings,
        result,
        rounds,
        step_over_candle_matmul,
        step_over_kernel_matmul,
        step_over_register_peak,
    })
}

impl TeacherStepJob {
    /// Creates a teacher run in a scratch folder and times its steps.
    pub fn run(&self, on_event: OnEvent) -> Result<StepReport<TeacherRunConfig>> {
        check_pairs(self.pairs)?;
        let mut machine = self.load.admit()?;
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
        let mut rounds = Vec::new();
        for round in 0..self.pairs {
            let warmup = if round == 0 { 3 } else { 0 };
            rounds.push(bench_teacher_step(&mut run, &data, warmup, self.steps)?);
        }
        machine.record_end();
        let settings = StepSettings {
            preset: Some(self.preset.clone()),
            depth: None,
            rays: self.rays,
            steps: self.steps,
            pairs: self.pairs,
            data: data_dir,
            config: cfg,
        };
        step_report("teacher-step", machine, settings, rounds)
    }
}

impl StudentStepJob {
    /// Creates a student run in a scratch folder and times its steps.
    pub fn run(&self, on_event: OnEvent) -> Result<StepReport<StudentRunConfig>> {
        check_pairs(self.pairs)?;
        let mut machine = self.load.admit()?;
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
        let mut rounds = Vec::new();
        for round in 0..self.pairs {
            let warmup = if round == 0 { 2 } else { 0 };
            rounds.push(bench_student_step(&mut run, &data, warmup, self.steps)?);
        }
        machine.record_end();
        let settings = StepSettings {
            preset: None,
            depth: Some(self.depth.clone()),
            rays: self.rays,
            steps: self.steps,
            pairs: self.pairs,
            data: data_dir,
            config: cfg,
        };
        step_report("student-step", machine, settings, rounds)
    }
}

impl<C: Serialize> StepReport<C> {
    /// Writes `{bench}.json` and `{bench}.md` (dashes as underscores) into `out`.
    pub fn write(&self, out: &Path) -> Result<Written> {
        write_bench_files(out, &self.bench.replace('-', "_"), self, markdown(self))
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

/// The report's table: one row per figure; the step's time and rates are the middle
/// round's, the ratios those over every round.
fn markdown<C>(report: &StepReport<C>) -> String {
    let (m, r) = (&report.machine, &report.result);
    format!(
        "| {} | value |\n|---|---|\n\
         | machine | {}, {} rayon threads |\n\
         | batch | {} rays, {:.0} hit the head's bounds, {} samples each{} |\n\
         | rounds | {} rounds of {} timed steps, each followed by the matmuls at the same shapes; ratios: median of the rounds (smallest-largest) |\n\
         | step time (middle round) | {:.3} s |\n\
         | throughput | {:.0} rays/s |\n\
         | effective rate (3 x forward FLOPs) | {:.1} GFLOP/s |\n\
         | cores busy | {:.2} |\n\
         | candle matmul at the same shapes | {:.1} GFLOP/s |\n\
         | step rate / candle matmul rate | {} |\n\
         | nldf kernel matmul at the same shapes | {:.1} GFLOP/s |\n\
         | step rate / kernel matmul rate | {} |\n\
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
        report.rounds.len(),
        r.steps,
        r.seconds_per_step,
        r.rays_per_s,
        r.effective_gflop_s,
        r.cores_busy,
        r.candle_matmul_gflop_s,
        report.step_over_candle_matmul.cell(),
        r.kernel_matmul_gflop_s,
        report.step_over_kernel_matmul.cell(),
        match (r.register_peak_gflop_s, &report.step_over_register_peak) {
            (Some(p), Some(f)) => format!("{p:.1} GFLOP/s (step rate / peak: {})", f.cell()),
            _ => "not measured (no FMA vectors)".into(),
        }
    )
}
