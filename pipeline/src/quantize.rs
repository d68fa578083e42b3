//! Quantization: `nldf export --int8` (for the ray graph and the frame graph) is written
//! here, above both export and the runtimes, because calibrating it means running the
//! model. The student's f32 graph with the input of every int8 product as an extra output
//! ([`nldf_export::calibration_model`]) runs in tract on the rays of training frames, each
//! with its own recorded audio, and the range of every such input becomes the fixed uint8
//! step and zero point of its product ([`nldf_export::export_student_int8`]). Fixed ranges
//! keep a ray's colour independent of the rays that share its batch, which ranges measured
//! per call would not.

use std::collections::HashMap;
use std::collections::hash_map::Entry;
use std::path::Path;

use nldf_core::audio::neighbourhood;
use nldf_core::camera::Camera;
use nldf_core::dataset::Dataset;
use nldf_core::rays::head_rays;
use nldf_export::{ActivationRanges, ExportReport, Tap, calibration_model, export_student_int8};
use nldf_model::contract::{ModelInfo, input_names};
use tract_onnx::prelude::*;

use crate::error::{Error, Result};

const NAME: &str = "tract (calibration)";

/// A failure of tract while calibrating, as nldf-infer reports a runtime's failure.
fn backend(e: impl std::fmt::Display) -> Error {
    nldf_infer::Error::backend(NAME, e).into()
}

/// Rays per calibration call.
const CALIBRATION_BATCH: usize = 4096;

/// One frame's calibration rays and its audio neighbourhood.
#[derive(Debug, Clone, PartialEq)]
pub struct CalibrationFrame {
    /// Ray origins and directions, `[n_rays, 3]` flat.
    pub origins: Vec<f32>,
    pub directions: Vec<f32>,
    /// `[att_frames, window, n_features]` flat.
    pub audio: Vec<f32>,
}

/// The rays meeting the head's bounds in `n_frames` training frames of the dataset at
/// `data`, spread evenly over the recording, each with its recorded audio: the rays the
/// student was trained on. The dataset's audio features must be the model's.
pub fn training_frames(
    data: &Path,
    info: &ModelInfo,
    n_frames: usize,
) -> Result<Vec<CalibrationFrame>> {
    let dataset = Dataset::load(data)?;
    let (window, features) = (dataset.audio.window, dataset.audio.n_features);
    if (window, features) != (info.audio.window, info.audio.n_features) {
        return Err(Error::Argument(format!(
            "{}: audio windows of {window} x {features} features, but the student reads {} \
             x {}: calibrate on the student's own training data",
            data.display(),
            info.audio.window,
            info.audio.n_features
        )));
    }
    if n_frames == 0 || dataset.train.is_empty() {
        return Err(Error::Argument(format!(
            "{}: no training frames to calibrate on",
            data.display()
        )));
    }
    let n = n_frames.min(dataset.train.len());
    let head = info.spec.head_range();
    Ok((0..n)
        .map(|i| {
            let frame = &dataset.train[i * dataset.train.len() / n];
            let camera = Camera {
                intrinsics: dataset.intrinsics,
                c2w: frame.c2w,
            };
            let rays = head_rays(&camera, &head).rays;
            CalibrationFrame {
                origins: rays.origins,
                directions: rays.directions,
                audio: neighbourhood(&dataset.audio, frame.aud_id, info.audio.att_frames),
            }
        })
        .collect())
}

/// Runs the calibration model of the student in `student_dir` on `frames` and returns the
/// range of every int8 product's input.
pub fn activation_ranges(
    student_dir: &Path,
    info: &ModelInfo,
    frames: &[CalibrationFrame],
) -> Result<ActivationRanges> {
    let (bytes, _, taps) = calibration_model(student_dir)?;
    ranges_of(&bytes, &taps, info, frames)
}

/// The ranges of `taps` in the calibration model `bytes` run on `frames`.
fn ranges_of(
    bytes: &[u8],
    taps: &[Tap],
    info: &ModelInfo,
    frames: &[CalibrationFrame],
) -> Result<ActivationRanges> {
    let mut parsed = tract_onnx::onnx()
        .model_for_read(&mut &bytes[..])
        .map_err(backend)?;
    parsed
        .set_input_names(input_names())
        .and_then(|()| parsed.select_outputs_by_name(taps.iter().map(|t| t.tensor.as_str())))
        .map_err(backend)?;
    let mut plans: HashMap<usize, std::sync::Arc<TypedRunnableModel>> = HashMap::new();
    let mut ranges = ActivationRanges::default();
    let audio_shape = info.audio.shape();
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let executor =
        tract_linalg::multithread::Executor::multithread_with_name(threads, "nldf-calibrate");
    for frame in frames {
        let n = frame.origins.len() / 3;
        for start in (0..n).step_by(CALIBRATION_BATCH) {
            let end = (start + CALIBRATION_BATCH).min(n);
            let rays = end - start;
            let plan = match plans.entry(rays) {
                Entry::Occupied(e) => e.into_mut(),
                Entry::Vacant(e) => e.insert(
                    parsed
                        .clone()
                        .with_input_fact(0, f32::fact([rays, 3]).into())
                        .and_then(|m| m.with_input_fact(1, f32::fact([rays, 3]).into()))
                        .and_then(|m| m.with_input_fact(2, f32::fact(audio_shape).into()))
                        .and_then(|m| m.with_input_fact(3, f32::fact([rays, 3]).into()))
                        .and_then(|m| m.into_optimized())
                        .and_then(|m| m.into_runnable())
                        .map_err(backend)?,
                ),
            };
            let inputs = (|| -> TractResult<TVec<TValue>> {
                // The taps all lie before the compositing: any background will do.
                Ok(tvec!(
                    Tensor::from_shape(&[rays, 3], &frame.origins[3 * start..3 * end])?.into(),
                    Tensor::from_shape(&[rays, 3], &frame.directions[3 * start..3 * end])?.into(),
                    Tensor::from_shape(&audio_shape, &frame.audio)?.into(),
                    Tensor::from_shape(&[rays, 3], &vec![0.0f32; 3 * rays])?.into(),
                ))
            })()
            .map_err(backend)?;
            let outputs =
                tract_linalg::multithread::multithread_tract_scope(executor.clone(), || {
                    plan.run(inputs)
                })
                .map_err(backend)?;
            for (tap, out) in taps.iter().zip(&outputs) {
                let view = out.to_plain_array_view::<f32>().map_err(backend)?;
                let values: Vec<f32> = view.iter().copied().collect();
                ranges.observe(&tap.product, &values);
            }
        }
    }
    check_every_tap(taps, &ranges)?;
    Ok(ranges)
}

fn check_every_tap(taps: &[Tap], ranges: &ActivationRanges) -> Result<()> {
    match taps.iter().find(|t| ranges.get(&t.product).is_none()) {
        Some(t) => Err(Error::Argument(format!(
            "calibration saw no finite value entering `{}`",
            t.product
        ))),
        None => Ok(()),
    }
}

/// Exports the student in `student_dir` with int8 products calibrated on `n_frames`
/// training frames of the dataset at `data` ([`training_frames`],
/// [`activation_ranges`]), written to `out`.
pub fn export_int8(
    student_dir: &Path,
    data: &Path,
    n_frames: usize,
    out: &Path,
) -> Result<ExportReport> {
    let ranges = calibrated_ranges(student_dir, data, n_frames, &[])?;
    Ok(export_student_int8(student_dir, out, &ranges)?)
}

/// The int8 products' input ranges of the student in `student_dir`, measured on `n_frames`
/// training frames of the dataset at `data`, with the products named in `keep_f32` kept in
/// f32 ([`keep_in_f32`]).
pub fn calibrated_ranges(
    student_dir: &Path,
    data: &Path,
    n_frames: usize,
    keep_f32: &[String],
) -> Result<ActivationRanges> {
    let (bytes, info, taps) = calibration_model(student_dir)?;
    let frames = training_frames(data, &info, n_frames)?;
    let mut ranges = ranges_of(&bytes, &taps, &info, &frames)?;
    keep_in_f32(&mut ranges, &taps, keep_f32)?;
    Ok(ranges)
}

/// Marks the products named in `names` to stay in f32 ([`ActivationRanges::keep_f32`]);
/// a name that is none of the student's int8 products (`taps`) is an error that lists them.
pub fn keep_in_f32(ranges: &mut ActivationRanges, taps: &[Tap], names: &[String]) -> Result<()> {
    for name in names {
        if !taps.iter().any(|t| &t.product == name) {
            let known: Vec<&str> = taps.iter().map(|t| t.product.as_str()).collect();
            return Err(Error::Argument(format!(
                "`{name}` is not one of the student's int8 products ({})",
                known.join(", ")
            )));
        }
        ranges.keep_f32(name);
    }
    Ok(())
}
