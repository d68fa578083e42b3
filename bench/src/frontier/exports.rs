//! The frontier's exports: every student of the run in every precision, and each export
//! opened in a runtime as a point that renders whole frames.

use std::cell::RefCell;
use std::path::{Path, PathBuf};

use nldf_export::{ActivationRanges, WeightType};
use nldf_infer::{BackendKind, BackendOptions, FrameRenderer, backend_for};
use nldf_train::job::{JobEvent, OnEvent};
use nldf_train::reports::eval::{FrameModel, student_short_name};
use nldf_train::trainers::student_trainer::StudentModel;
use nldf_train::trainers::upsampler_trainer::UpsampledModel;

use super::points::OnnxPoint;
use super::shared::{PRECISIONS, precision_name};
use crate::error::{Error, Result, chain, create_dir};

/// One student exported in one precision.
pub(crate) struct Export {
    /// The student's folder name.
    pub(crate) student: String,
    pub(crate) describe: String,
    /// The student's name in plots ([`student_short_name`]).
    pub(crate) short: String,
    pub(crate) step: usize,
    pub(crate) macs_per_ray: f64,
    pub(crate) precision: WeightType,
    pub(crate) path: PathBuf,
}

/// Exports every student of the run in every precision into `dir`; the int8 exports are
/// calibrated on `calibration_frames` training frames of `data`. A student whose weights do
/// not fit half precision has no f16 point (a note says so).
pub(crate) fn export_all(
    students: &[StudentModel],
    data: &Path,
    calibration_frames: usize,
    dir: &Path,
    on_event: OnEvent,
) -> Result<Vec<Export>> {
    create_dir(dir)?;
    let mut out = Vec::new();
    for s in students {
        let name = s.label();
        for w in PRECISIONS {
            let path = dir.join(format!("{name}.{}.onnx", precision_name(w)));
            let report = match w {
                WeightType::Int8 => {
                    nldf_pipeline::quantize::export_int8(&s.dir, data, calibration_frames, &path)
                        .map(|_| ())
                        .map_err(Error::from)
                }
                _ => nldf_export::export_student(&s.dir, &path, w)
                    .map(|_| ())
                    .map_err(Error::from),
            };
            match report {
                Ok(()) => {
                    on_event(&JobEvent::Note(format!("exported {}", path.display())));
                    out.push(Export {
                        student: name.clone(),
                        describe: s.describe(),
                        short: student_short_name(&s.cfg),
                        step: s.step,
                        macs_per_ray: s.macs_per_ray(),
                        precision: w,
                        path,
                    });
                }
                Err(e) if w == WeightType::F16 => on_event(&JobEvent::Note(format!(
                    "{name}: no fp16 point: {}",
                    chain(&e)
                ))),
                Err(e) => return Err(e.context(format!("exporting {name}"))),
            }
        }
    }
    Ok(out)
}

/// Exports the upsampled ray graph of each of `job.upsamplers` (the run's learned
/// upsamplers, found by `val`'s plan) over the student it reads, in fp16 and with int8
/// products calibrated as the students' are (`job.int8_f32` kept in f32), into
/// `OUT/models`. Each is a point named `<student>+<upsampler>`; its multiply-adds per ray
/// are the upsampler's estimate (the student's share of a coarse ray and the CNN's cost of
/// a pixel).
pub(crate) fn export_upsampled(
    job: &super::shared::FrontierJob,
    val: &nldf_train::job::eval::EvalPlan,
    on_event: OnEvent,
) -> Result<Vec<Export>> {
    let dir = job.out.join("models");
    let mut out = Vec::new();
    for name in &job.upsamplers {
        let (up, _) = val
            .upsamplers
            .iter()
            .find(|(u, _)| u.label() == *name)
            .ok_or_else(|| {
                Error::Missing(format!(
                    "{} has no trained upsampler `{name}`",
                    job.run.display()
                ))
            })?;
        let student = &up.student;
        let factor = up.cfg.model.factor;
        let ranges = nldf_pipeline::quantize::calibrated_ranges(
            &student.dir,
            &job.data,
            job.calibration_frames,
            &job.int8_f32,
        )?;
        for w in [WeightType::F16, WeightType::Int8] {
            let path = dir.join(format!("{name}.rays.{}.onnx", precision_name(w)));
            export_upsampled_rays(up, &path, w, &ranges)?;
            on_event(&JobEvent::Note(format!("exported {}", path.display())));
            out.push(Export {
                student: format!("{}+{name}", student.label()),
                describe: format!(
                    "{} under the learned upsampler `{name}` (x{factor})",
                    student.describe()
                ),
                short: format!("{} x{factor}", student_short_name(&student.cfg)),
                step: student.step,
                macs_per_ray: up.macs_per_ray(),
                precision: w,
                path,
            });
        }
    }
    Ok(out)
}

/// `e` in `kind`, rendering frames of `size` (`None`: the model's own), each `upscale` times
/// smaller (a ray through the centre of each `upscale x upscale` block) and then upscaled.
pub(crate) fn open_point(
    e: &Export,
    kind: BackendKind,
    threads: usize,
    batch: usize,
    size: Option<u32>,
    upscale: u32,
) -> Result<OnnxPoint> {
    let model = nldf_model::read_model(&e.path)?;
    // The points take turns frame by frame: a pool left spinning after its call would run
    // beside the next point's.
    let backend = backend_for(
        &model,
        kind,
        BackendOptions {
            batch_size: batch,
            threads,
            spin: false,
        },
    )?;
    let renderer = match size {
        Some(size) if upscale > 1 => FrameRenderer::for_upscaling(backend, size, upscale)?,
        _ => FrameRenderer::new(backend, size)?,
    };
    Ok(OnnxPoint {
        student: e.student.clone(),
        describe: e.describe.clone(),
        short: e.short.clone(),
        precision: e.precision,
        kind,
        step: e.step,
        macs_per_ray: e.macs_per_ray,
        path: e.path.clone(),
        renderer: RefCell::new(renderer),
        upscale: upscale.max(1),
        seconds: RefCell::new(Vec::new()),
    })
}

/// Exports the ray graph of `up` (the upsampler over its student) to `path` in `w`; int8
/// takes its products' ranges from `ranges`, the other precisions ignore them.
pub(crate) fn export_upsampled_rays(
    up: &UpsampledModel,
    path: &Path,
    w: WeightType,
    ranges: &ActivationRanges,
) -> Result<()> {
    let student = &up.student.dir;
    match w {
        WeightType::Int8 => {
            nldf_export::export_student_upsampled_int8(student, &up.dir, path, ranges)?
        }
        _ => nldf_export::export_student_upsampled(student, &up.dir, path, w)?,
    };
    Ok(())
}
