//! `nldf bench upsampler`: the frontier's rows for a run with a learned upsampler, at the
//! run's own size (256 or 512). The same held-out frames are rendered, taking turns frame
//! by frame, by the student's ray graph on every pixel ("native rays"), by the ray graph on
//! the upsampler's coarse grid upscaled bilinearly ("bilinear"), by the frame graph with the
//! upsampler inside and by nldf's renderer on the ray graph with the upsampler inside, each
//! in f32 and f16 (the upsampled graphs in onnxruntime and tract; the upsampled ray graph
//! also with the student's products in int8), and by the teacher in candle; each is scored (PSNR and SSIM on the whole frame and
//! in the head, mouth PSNR) and timed per whole frame with 2 threads (median). Each frame
//! is a pair for any two ways (both rendered it in turn), so every row's speed against the
//! student's native rays in f32 onnxruntime, and each precision's against the others of its
//! way and runtime, is a ratio over those pairs ([`crate::repeats`]).
//! `upsampler.json` and `upsampler.md` hold the rows with the machine, commit and settings.

use std::cell::RefCell;
use std::path::{Path, PathBuf};

use nldf_core::dataset::Split;
use nldf_core::stats::median;
use nldf_export::{ActivationRanges, WeightType};
use nldf_infer::BackendKind;
use nldf_infer::frame_graph::FrameGraph;
use nldf_model::FrameGraphFile;
use nldf_train::job::eval::{EvalJob, EvalPlan};
use nldf_train::job::{JobEvent, OnEvent};
use nldf_train::reports::eval::{EvalReport, FrameModel};
use nldf_train::trainers::upsampler_trainer::UpsampledModel;

use super::exports::{Export, export_upsampled_rays, open_point};
use super::front::{SplitScore, paired_ratio, score};
use super::points::{OnnxPoint, Timed};
use super::shared::{THREADS, eval_split, precision_name};
use super::upsampled_point::UpsampledPoint;
use super::upsampler_report::markdown;
pub use super::upsampler_report::{PrecisionRatio, UpsamplerBenchReport, UpsamplerRow};
use crate::error::{Error, Result, create_dir};
use crate::load::LoadGate;
use crate::report::{Written, write_bench_files};

/// What `nldf bench upsampler` was asked to do.
#[derive(Debug, Clone)]
pub struct UpsamplerBench {
    /// The run: its teacher, the upsampler `upsampler` and the student it reads.
    pub run: PathBuf,
    /// The data the run was trained on (its size is the output's).
    pub data: PathBuf,
    /// The upsampler's folder in the run.
    pub upsampler: String,
    pub out: PathBuf,
    /// At most this many frames of each split.
    pub frames: Option<usize>,
    pub splits: Vec<Split>,
    /// Render the teacher too (slow at 512: seconds a frame).
    pub teacher: bool,
    /// Rays per network call of the ray graphs.
    pub batch: usize,
    /// The student's products kept in f32 in the int8 ray graph (mixed precision).
    pub int8_f32: Vec<String>,
    /// The load limit at the start.
    pub load: LoadGate,
}

/// Adds a row: way, precision, runtime, grid side, the model's label, seconds of each frame.
type AddRow<'a> = dyn FnMut(&str, &str, &str, u32, String, Vec<f64>) + 'a;

/// The graphs the benchmark renders with, exported under `models/`.
struct Exports {
    /// The student's ray graph in each precision.
    students: Vec<Export>,
    /// The upsampled frame graph in each precision.
    frames: Vec<(WeightType, FrameGraphFile)>,
    /// The upsampled ray graph in each precision, int8 last.
    rays: Vec<Export>,
}

/// The ways of rendering, each open in its runtimes.
struct Points {
    native: Vec<OnnxPoint>,
    bilinear: Vec<OnnxPoint>,
    upsampled: Vec<UpsampledPoint>,
    upsampled_rays: Vec<OnnxPoint>,
}

impl UpsamplerBench {
    /// Exports, renders, scores and times; writes `upsampler.json` and `upsampler.md`.
    pub fn run(&self, on_event: OnEvent) -> Result<(UpsamplerBenchReport, Written)> {
        nldf_infer::ort_library::OrtSearch::from_env()
            .find()
            .map_err(|e| Error::from(e).context("bench upsampler runs onnxruntime"))?;
        let mut machine = self.load.admit()?;
        let first = self.eval_job(self.splits.first().copied().unwrap_or(Split::Val));
        let plan = first.plan(&mut *on_event)?;
        let (up, _) = plan
            .upsamplers
            .iter()
            .find(|(u, _)| u.label() == self.upsampler)
            .ok_or_else(|| {
                Error::Missing(format!(
                    "{} has no trained upsampler `{}`",
                    self.run.display(),
                    self.upsampler
                ))
            })?;
        let factor = up.cfg.model.factor;
        let size = plan.data.dataset.intrinsics.width;
        let exports = self.export_models(up, &mut *on_event)?;
        let points = self.open_points(&exports, up, size, factor)?;
        let teacher = Timed::new(&plan.teacher, true, true);
        let reports = self.evaluate(&first, &plan, &teacher, &points, on_event)?;
        let mut rows = self.rows(&reports, &teacher, &points, size, factor);
        machine.record_end();
        let precisions = speed_ratios(&mut rows);
        let report = UpsamplerBenchReport {
            machine,
            run: self.run.display().to_string(),
            upsampler: self.upsampler.clone(),
            factor,
            frames: self.frames,
            threads: THREADS,
            int8_f32: self.int8_f32.clone(),
            rows,
            precisions,
        };
        let markdown = markdown(&report, &self.splits);
        let written = write_bench_files(&self.out, "upsampler", &report, markdown)?;
        Ok((report, written))
    }

    /// Exports the student's ray graph and the upsampled frame and ray graphs in f32 and
    /// f16, and the upsampled ray graph with int8 products, under `OUT/models`.
    fn export_models(&self, up: &UpsampledModel, on_event: OnEvent) -> Result<Exports> {
        let factor = up.cfg.model.factor;
        let student = &up.student;
        let models_dir = self.out.join("models");
        create_dir(&models_dir)?;
        let mut exports = Vec::new();
        let mut graphs = Vec::new();
        let mut ray_graphs = Vec::new();
        // An upsampled ray graph, labelled after the upsampler.
        let ray_export = |precision: WeightType, path: PathBuf| Export {
            student: format!("{}.rays", self.upsampler),
            describe: format!("{} with upsampler x{factor}", student.describe()),
            short: nldf_train::reports::eval::student_short_name(&student.cfg),
            step: up.step,
            macs_per_ray: up.macs_per_ray(),
            precision,
            path,
        };
        for w in [WeightType::F32, WeightType::F16] {
            let p = precision_name(w);
            let path = models_dir.join(format!("{}.{p}.onnx", student.label()));
            nldf_export::export_student(&student.dir, &path, w)?;
            exports.push(Export {
                student: student.label(),
                describe: student.describe(),
                short: nldf_train::reports::eval::student_short_name(&student.cfg),
                step: student.step,
                macs_per_ray: student.macs_per_ray(),
                precision: w,
                path,
            });
            let frame = models_dir.join(format!("{}.frame.{p}.onnx", self.upsampler));
            nldf_export::export_frame_upsampled(&student.dir, &up.dir, &frame, w)?;
            graphs.push((w, nldf_model::read_frame_model(&frame)?));
            let rays = models_dir.join(format!("{}.rays.{p}.onnx", self.upsampler));
            export_upsampled_rays(up, &rays, w, &ActivationRanges::default())?;
            ray_graphs.push(ray_export(w, rays));
            on_event(&JobEvent::Note(format!(
                "exported the student's ray graph and the upsampled frame and ray graphs in {p}"
            )));
        }
        // The upsampled ray graph with the student's products in int8, calibrated as the
        // frontier calibrates (16 training frames).
        let ranges = nldf_pipeline::quantize::calibrated_ranges(
            &student.dir,
            &self.data,
            16,
            &self.int8_f32,
        )?;
        let rays = models_dir.join(format!("{}.rays.int8.onnx", self.upsampler));
        export_upsampled_rays(up, &rays, WeightType::Int8, &ranges)?;
        ray_graphs.push(ray_export(WeightType::Int8, rays));
        on_event(&JobEvent::Note(
            "exported the upsampled ray graph with int8 products".into(),
        ));
        Ok(Exports {
            students: exports,
            frames: graphs,
            rays: ray_graphs,
        })
    }

    /// Opens the ways of rendering, in the tables' order.
    fn open_points(
        &self,
        exports: &Exports,
        up: &UpsampledModel,
        size: u32,
        factor: usize,
    ) -> Result<Points> {
        let mut native = Vec::new();
        let mut bilinear = Vec::new();
        for e in &exports.students {
            native.push(open_point(
                e,
                BackendKind::Ort,
                THREADS,
                self.batch,
                None,
                1,
            )?);
            bilinear.push(open_point(
                e,
                BackendKind::Ort,
                THREADS,
                self.batch,
                Some(size),
                factor as u32,
            )?);
        }
        let mut upsampled = Vec::new();
        for (w, model) in &exports.frames {
            for kind in [BackendKind::Ort, BackendKind::Tract] {
                upsampled.push(UpsampledPoint {
                    label: format!("{}.{}.{}", self.upsampler, precision_name(*w), kind.name()),
                    precision: *w,
                    kind,
                    step: up.step,
                    graph: RefCell::new(FrameGraph::open(model, kind, THREADS)?),
                    model: model.clone(),
                    split: std::cell::Cell::new(Split::Val),
                    wave: RefCell::new(None),
                    seconds: RefCell::new(Vec::new()),
                });
            }
        }
        let mut upsampled_rays = Vec::new();
        for e in &exports.rays {
            for kind in [BackendKind::Ort, BackendKind::Tract] {
                upsampled_rays.push(open_point(e, kind, THREADS, self.batch, None, 1)?);
            }
        }
        Ok(Points {
            native,
            bilinear,
            upsampled,
            upsampled_rays,
        })
    }

    /// Renders and scores every split, the ways of rendering taking turns frame by frame.
    fn evaluate(
        &self,
        first: &EvalJob,
        plan: &EvalPlan,
        teacher: &Timed<'_>,
        points: &Points,
        on_event: OnEvent,
    ) -> Result<Vec<Vec<EvalReport>>> {
        let mut reports: Vec<Vec<EvalReport>> = Vec::new();
        for &split in &self.splits {
            let other;
            let data = if split == first.split {
                &plan.data
            } else {
                other = self.eval_job(split).plan(&mut *on_event)?;
                &other.data
            };
            let mut models: Vec<&dyn FrameModel> = Vec::new();
            if self.teacher {
                models.push(teacher);
            }
            for p in points.native.iter().chain(&points.bilinear) {
                models.push(p);
            }
            for p in &points.upsampled {
                p.split.set(split);
                models.push(p);
            }
            for p in &points.upsampled_rays {
                models.push(p);
            }
            let out = self.out.join(split.name());
            let evaluation = eval_split(&models, data, split, self.frames, &out, &mut *on_event)?;
            reports.push(evaluation.models);
        }
        Ok(reports)
    }

    /// One row a way of rendering, precision and runtime, in the tables' order.
    fn rows(
        &self,
        reports: &[Vec<EvalReport>],
        teacher: &Timed<'_>,
        points: &Points,
        size: u32,
        factor: usize,
    ) -> Vec<UpsamplerRow> {
        let scores_of = |label: &str| -> Vec<SplitScore> {
            reports
                .iter()
                .filter_map(|rs| rs.iter().find(|r| r.label == label).map(score))
                .collect()
        };
        let timed = |s: &RefCell<Vec<f64>>| s.borrow().clone();
        let grid = size / factor as u32;
        let mut rows = Vec::new();
        let mut row =
            |way: &str, precision: &str, runtime: &str, grid: u32, label: String, f: Vec<f64>| {
                let s = median(&f);
                rows.push(UpsamplerRow {
                    way: way.into(),
                    precision: precision.into(),
                    runtime: runtime.into(),
                    size,
                    grid,
                    s_per_frame: s,
                    fps: if s > 0.0 { 1.0 / s } else { f64::NAN },
                    scores: scores_of(&label),
                    speed_against_native: None,
                    frame_seconds: f,
                });
            };
        if self.teacher {
            row(
                "teacher",
                "fp32",
                "candle",
                size,
                teacher.label(),
                timed(&teacher.seconds),
            );
        }
        let onnx_rows = |row: &mut AddRow<'_>, way: &str, grid: u32, points: &[OnnxPoint]| {
            for p in points {
                let s = timed(&p.seconds);
                row(
                    way,
                    precision_name(p.precision),
                    p.kind.name(),
                    grid,
                    p.label(),
                    s,
                );
            }
        };
        onnx_rows(&mut row, "native rays", size, &points.native);
        onnx_rows(&mut row, "bilinear", grid, &points.bilinear);
        for p in &points.upsampled {
            let s = timed(&p.seconds);
            row(
                "upsampler, frame graph",
                precision_name(p.precision),
                p.kind.name(),
                grid,
                p.label(),
                s,
            );
        }
        onnx_rows(
            &mut row,
            "upsampler, ray graph",
            grid,
            &points.upsampled_rays,
        );
        rows
    }

    fn eval_job(&self, split: Split) -> EvalJob {
        EvalJob {
            run: self.run.clone(),
            data: self.data.clone(),
            split,
            frames: self.frames,
            out: None,
            against: None,
        }
    }
}

/// Sets each row's speed against the student's native rays in f32 onnxruntime, and returns
/// each precision against the others of its way and runtime (lower precision first: fp16
/// and int8 against fp32, int8 against fp16); every ratio frame by frame.
fn speed_ratios(rows: &mut [UpsamplerRow]) -> Vec<PrecisionRatio> {
    let native = rows
        .iter()
        .find(|r| r.way == "native rays" && r.precision == "fp32" && r.runtime == "ort")
        .map(|r| r.frame_seconds.clone());
    if let Some(native) = &native {
        for r in rows.iter_mut() {
            r.speed_against_native = paired_ratio(native, &r.frame_seconds);
        }
    }
    let order = ["fp32", "fp16", "int8"];
    let rank = |p: &str| order.iter().position(|o| *o == p);
    let mut out = Vec::new();
    for a in rows.iter() {
        for b in rows.iter() {
            let lower =
                matches!((rank(&a.precision), rank(&b.precision)), (Some(x), Some(y)) if x > y);
            if a.way != b.way || a.runtime != b.runtime || !lower {
                continue;
            }
            if let Some(speed) = paired_ratio(&b.frame_seconds, &a.frame_seconds) {
                out.push(PrecisionRatio {
                    way: a.way.clone(),
                    runtime: a.runtime.clone(),
                    precision: a.precision.clone(),
                    against: b.precision.clone(),
                    speed,
                });
            }
        }
    }
    out
}

/// The default output folder: `RUN/bench_upsampler`.
pub fn default_out(run: &Path) -> PathBuf {
    run.join("bench_upsampler")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(way: &str, precision: &str, runtime: &str, seconds: &[f64]) -> UpsamplerRow {
        UpsamplerRow {
            way: way.into(),
            precision: precision.into(),
            runtime: runtime.into(),
            size: 256,
            grid: 64,
            s_per_frame: median(seconds),
            fps: 1.0 / median(seconds),
            scores: Vec::new(),
            speed_against_native: None,
            frame_seconds: seconds.to_vec(),
        }
    }

    /// Every row against native rays in fp32 onnxruntime, and each lower precision
    /// against the higher ones of its own way and runtime only, frame by frame.
    #[test]
    fn speeds_pair_frames_within_a_way_and_runtime() {
        let native = [0.10, 0.11, 0.10, 0.12, 0.10];
        let f32_rays = [0.05, 0.05, 0.06, 0.05, 0.05];
        // int8 faster on the median frame, slower on one: no difference against fp16.
        let f16_rays = [0.040, 0.041, 0.040, 0.040, 0.040];
        let int8_rays = [0.036, 0.037, 0.044, 0.036, 0.037];
        let mut rows = vec![
            row("native rays", "fp32", "ort", &native),
            row("upsampler, ray graph", "fp32", "ort", &f32_rays),
            row("upsampler, ray graph", "fp16", "ort", &f16_rays),
            row("upsampler, ray graph", "int8", "ort", &int8_rays),
            row("upsampler, ray graph", "fp16", "tract", &f16_rays),
        ];
        let precisions = speed_ratios(&mut rows);
        let native_speed = rows[1].speed_against_native.unwrap();
        assert!((native_speed.median - 2.0).abs() < 1e-9, "{native_speed:?}");
        assert_eq!(native_speed.verdict, crate::repeats::Verdict::Above);
        let names: Vec<(&str, &str, &str)> = precisions
            .iter()
            .map(|p| (p.runtime.as_str(), p.precision.as_str(), p.against.as_str()))
            .collect();
        assert_eq!(
            names,
            [
                ("ort", "fp16", "fp32"),
                ("ort", "int8", "fp32"),
                ("ort", "int8", "fp16"),
            ]
        );
        let int8_f16 = &precisions[2].speed;
        assert!(int8_f16.median > 1.0, "{int8_f16:?}");
        assert_eq!(int8_f16.verdict, crate::repeats::Verdict::NoDifference);
    }
}
