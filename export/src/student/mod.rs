//! The student as one ONNX graph: beam encoding from ray origins and directions (paper
//! section 3.2), the audio encoder with its attention (AD-NeRF), the residual MLP and the
//! segment sum (Eq. 7). It computes what nldf-train's `Student::render_rays` computes.

mod audio;
mod beam;
mod mlp;
mod ops;

use nldf_model::contract::{
    self, AudioInput, GRAPH_NAME, INPUT_AUDIO, INPUT_BACKGROUND, INPUT_DIRECTIONS, INPUT_ORIGINS,
    ModelInfo, NetworkShape, OUTPUT_OPACITY, OUTPUT_RGB, OUTPUT_SEGMENTS, RAY_AXIS,
};
use nldf_model::onnx::{DataType, GraphProto, ModelProto, OperatorSetIdProto};
use std::path::{Path, PathBuf};

use crate::checkpoint::StudentCheckpoint;
use crate::error::{Error, Result};
use crate::graph::{ActivationRanges, Dim, GraphBuilder, Tap, WeightType};
use audio::audio_code;
use beam::encode_beams;
use mlp::residual_mlp;

/// What [`export_student`] wrote.
#[derive(Debug, Clone)]
pub struct ExportReport {
    /// The model file.
    pub path: PathBuf,
    /// Its size in bytes.
    pub bytes: usize,
    /// Values held by its initializers (weights and constants).
    pub n_values: usize,
    /// Its metadata.
    pub info: ModelInfo,
}

/// Exports the student in `student_dir` (`RUN/student/`) to `out`, written atomically.
/// With [`WeightType::F16`] the weights are stored in half precision and cast back to f32
/// in the graph; [`WeightType::Int8`] needs calibrated ranges: see
/// [`export_student_int8`].
pub fn export_student(student_dir: &Path, out: &Path, weights: WeightType) -> Result<ExportReport> {
    let ckpt = StudentCheckpoint::open(student_dir)?;
    check_f16_range(&ckpt, student_dir, weights)?;
    let (model, info, n_values) = student_model(&ckpt, weights)?;
    write_model(&model, info, n_values, out)
}

/// Under [`WeightType::F16`], refuses a student whose largest weight half precision cannot
/// hold.
pub(crate) fn check_f16_range(
    ckpt: &StudentCheckpoint,
    student_dir: &Path,
    weights: WeightType,
) -> Result<()> {
    if weights == WeightType::F16
        && let Some((name, largest)) = ckpt.largest_weight()
        && largest > half::f16::MAX.to_f32()
    {
        return Err(Error::invalid(
            student_dir.join(nldf_core::run_files::MODEL_FILE),
            format!(
                "weight `{name}` reaches {largest:e}, beyond half precision's {}: export \
                 without --fp16",
                half::f16::MAX
            ),
        ));
    }
    Ok(())
}

/// Exports the student in `student_dir` with int8 products ([`WeightType::Int8`]) whose
/// inputs have the `ranges` measured on calibration rays by running
/// [`calibration_model`]'s graph.
pub fn export_student_int8(
    student_dir: &Path,
    out: &Path,
    ranges: &ActivationRanges,
) -> Result<ExportReport> {
    let ckpt = StudentCheckpoint::open(student_dir)?;
    let (model, info, n_values, _) = build(&ckpt, GraphBuilder::int8(ranges.clone()))?;
    write_model(&model, info, n_values, out)
}

/// The f32 model of the student in `student_dir` that also outputs the input of every
/// product [`WeightType::Int8`] does in integers, to calibrate their ranges: its encoded
/// bytes, its metadata, and those products ([`Tap::tensor`] names the extra output of
/// each).
pub fn calibration_model(student_dir: &Path) -> Result<(Vec<u8>, ModelInfo, Vec<Tap>)> {
    let ckpt = StudentCheckpoint::open(student_dir)?;
    let (mut model, info, _, taps) = build(&ckpt, GraphBuilder::new(WeightType::F32))?;
    if let Some(graph) = model.graph.as_mut() {
        for tap in &taps {
            graph.output.push(crate::graph::value_info(
                &tap.tensor,
                DataType::Float,
                &[Dim::Symbolic(RAY_AXIS.to_string()), Dim::Fixed(tap.width)],
            ));
        }
    }
    Ok((prost::Message::encode_to_vec(&model), info, taps))
}

/// The error for an int8 export asked for without calibrated ranges; `flags` are the
/// export's other flags as `nldf export` spells them (`"--frame "`), to name the command
/// that measures them.
pub(crate) fn needs_ranges(flags: &str) -> Error {
    Error::Calibration(format!(
        "the activations' ranges must be measured on training rays first \
         (`nldf export {flags}--int8 --data DIR` does it)"
    ))
}

/// Encodes `model` and writes it to `out` atomically.
pub(crate) fn write_model(
    model: &ModelProto,
    info: ModelInfo,
    n_values: usize,
    out: &Path,
) -> Result<ExportReport> {
    let bytes = prost::Message::encode_to_vec(model);
    if let Some(dir) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    }
    nldf_core::files::write_atomic(out, &bytes)?;
    Ok(ExportReport {
        path: out.to_path_buf(),
        bytes: bytes.len(),
        n_values,
        info,
    })
}

/// The metadata of `ckpt`'s model whose graph is `graph`.
pub fn model_info(ckpt: &StudentCheckpoint, graph: &GraphProto) -> ModelInfo {
    let s = &ckpt.shape;
    ModelInfo {
        spec: ckpt.spec.clone(),
        beam: s.beam,
        segments: s.segments,
        audio: AudioInput {
            att_frames: s.audio.att_frames,
            window: s.audio.window,
            n_features: s.audio.n_features,
            attention: s.attention,
            ahead: s.audio.ahead,
        },
        network: NetworkShape {
            depth: s.depth,
            width: s.width,
            audio_dim: s.audio.dim,
        },
        step: ckpt.step,
        weights_checksum: contract::weights_checksum(graph),
        background_png: ckpt.background_png.clone(),
        upsample: None,
    }
}

/// The ONNX model of `ckpt`, its metadata and the number of values its initializers hold.
/// [`WeightType::Int8`] needs calibrated ranges: see [`export_student_int8`].
pub fn student_model(
    ckpt: &StudentCheckpoint,
    weights: WeightType,
) -> Result<(ModelProto, ModelInfo, usize)> {
    if weights == WeightType::Int8 {
        return Err(needs_ranges(""));
    }
    let (model, info, n_values, _) = build(ckpt, GraphBuilder::new(weights))?;
    Ok((model, info, n_values))
}

/// The ONNX model of `ckpt` built with `g`, its metadata, the number of values its
/// initializers hold, and the products [`WeightType::Int8`] does in integers.
fn build(
    ckpt: &StudentCheckpoint,
    mut g: GraphBuilder,
) -> Result<(ModelProto, ModelInfo, usize, Vec<Tap>)> {
    let s = &ckpt.shape;
    let rays = Dim::Symbolic(RAY_AXIS.to_string());
    let (origins, directions, audio) = ray_inputs(&mut g, ckpt);
    let background = g.input(
        INPUT_BACKGROUND,
        DataType::Float,
        &[rays.clone(), Dim::Fixed(3)],
    );
    student_nodes(
        &mut g,
        ckpt,
        (&origins, &directions),
        &audio,
        Some(&background),
    )?;
    g.output(OUTPUT_RGB, DataType::Float, &[rays.clone(), Dim::Fixed(3)]);
    g.output(
        OUTPUT_SEGMENTS,
        DataType::Float,
        &[rays.clone(), Dim::Fixed(s.segments), Dim::Fixed(3)],
    );
    g.output(OUTPUT_OPACITY, DataType::Float, &[rays, Dim::Fixed(1)]);
    let n_values = g.n_initializer_values();
    let doc = format!(
        "NLDF student: {} x {} residual MLP over beams of K = {} points with L = {} \
         frequencies and a {}-d audio code, M = {} segments. Inputs {INPUT_ORIGINS} and \
         {INPUT_DIRECTIONS} [{RAY_AXIS}, 3], {INPUT_AUDIO} [{}, {}, {}]; outputs {OUTPUT_RGB} \
         [{RAY_AXIS}, 3] and {OUTPUT_SEGMENTS} [{RAY_AXIS}, {}, 3]. With opacity: input \
         {INPUT_BACKGROUND} [{RAY_AXIS}, 3], output {OUTPUT_OPACITY} [{RAY_AXIS}, 1], and \
         {OUTPUT_RGB} = sum of the segments + (1 - {OUTPUT_OPACITY}) {INPUT_BACKGROUND}.",
        s.depth,
        s.width,
        s.beam.n_points,
        s.beam.n_freqs,
        s.audio.dim,
        s.segments,
        s.audio.att_frames,
        s.audio.window,
        s.audio.n_features,
        s.segments,
    );
    let taps = g.taps().to_vec();
    let graph = g.finish(GRAPH_NAME, &doc);
    let info = model_info(ckpt, &graph);
    let metadata = info.to_metadata();
    Ok((model_proto(graph, doc, metadata), info, n_values, taps))
}

/// Every ray graph's first inputs: [`INPUT_ORIGINS`] and [`INPUT_DIRECTIONS`] `[n_rays,
/// 3]`, [`INPUT_AUDIO`] `[att_frames, window, n_features]`; their names.
pub(crate) fn ray_inputs(
    g: &mut GraphBuilder,
    ckpt: &StudentCheckpoint,
) -> (String, String, String) {
    let a = &ckpt.shape.audio;
    let rays = [Dim::Symbolic(RAY_AXIS.to_string()), Dim::Fixed(3)];
    let origins = g.input(INPUT_ORIGINS, DataType::Float, &rays);
    let directions = g.input(INPUT_DIRECTIONS, DataType::Float, &rays);
    let audio = g.input(
        INPUT_AUDIO,
        DataType::Float,
        &[
            Dim::Fixed(a.att_frames),
            Dim::Fixed(a.window),
            Dim::Fixed(a.n_features),
        ],
    );
    (origins, directions, audio)
}

/// The model around `graph`: the contract's IR version and opset, nldf as producer, `doc`
/// and the `metadata` entries.
pub(crate) fn model_proto(
    graph: GraphProto,
    doc: String,
    metadata: Vec<nldf_model::onnx::StringStringEntryProto>,
) -> ModelProto {
    ModelProto {
        ir_version: Some(contract::IR_VERSION),
        opset_import: vec![OperatorSetIdProto {
            domain: Some(String::new()),
            version: Some(contract::OPSET),
        }],
        producer_name: Some(contract::PRODUCER.to_string()),
        producer_version: Some(env!("CARGO_PKG_VERSION").to_string()),
        domain: Some(String::new()),
        model_version: Some(1),
        doc_string: Some(doc),
        graph: Some(graph),
        metadata_props: metadata,
    }
}

/// The student's nodes on rays `(origins, directions)` with the audio neighbourhood
/// `windows`: beam encoding, audio code and residual MLP. They compute the tensors
/// [`OUTPUT_RGB`] (composited over `background` when given), [`OUTPUT_SEGMENTS`] and
/// [`OUTPUT_OPACITY`]; the caller declares which are graph outputs.
///
/// # Shapes
/// - `origins`, `directions`, `background`: `[n_rays, 3]`
/// - `windows`: `[att_frames, window, n_features]`
pub(crate) fn student_nodes(
    g: &mut GraphBuilder,
    ckpt: &StudentCheckpoint,
    (origins, directions): (&str, &str),
    windows: &str,
    background: Option<&str>,
) -> Result<()> {
    let beams = encode_beams(g, ckpt, origins, directions);
    let code = audio_code(g, ckpt, windows)?;
    residual_mlp(g, ckpt, &beams, &code, background)
}
