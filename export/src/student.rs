//! The student as one ONNX graph: beam encoding from ray origins and directions (paper
//! section 3.2), the audio encoder with its attention (AD-NeRF), the residual MLP and the
//! segment sum (Eq. 7). It computes what nldf-train's `Student::render_rays` computes.

use std::path::{Path, PathBuf};

use nldf_core::beam::{BeamAnchor, MIN_DIRECTION_LENGTH};
use nldf_core::encoding::MAX_COORD;

use crate::checkpoint::StudentCheckpoint;
use crate::contract::{
    self, AudioInput, GRAPH_NAME, INPUT_AUDIO, INPUT_BACKGROUND, INPUT_DIRECTIONS, INPUT_ORIGINS,
    ModelInfo, NetworkShape, OUTPUT_OPACITY, OUTPUT_RGB, OUTPUT_SEGMENTS, RAY_AXIS,
};
use crate::error::{Error, Result};
use crate::graph::{
    ActivationRanges, Dim, GraphBuilder, Tap, WeightType, attr_float, attr_int, attr_ints,
};
use crate::onnx::{DataType, GraphProto, ModelProto, OperatorSetIdProto};

/// AD-NeRF's LeakyReLU slope.
const SLOPE: f32 = 0.02;

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
        opacity: s.opacity,
        audio: AudioInput {
            att_frames: s.audio.att_frames,
            window: s.audio.window,
            n_features: s.audio.n_features,
            attention: s.attention,
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
    let background = s.opacity.then(|| {
        g.input(
            INPUT_BACKGROUND,
            DataType::Float,
            &[rays.clone(), Dim::Fixed(3)],
        )
    });
    student_nodes(
        &mut g,
        ckpt,
        (&origins, &directions),
        &audio,
        background.as_deref(),
    )?;
    g.output(OUTPUT_RGB, DataType::Float, &[rays.clone(), Dim::Fixed(3)]);
    g.output(
        OUTPUT_SEGMENTS,
        DataType::Float,
        &[rays.clone(), Dim::Fixed(s.segments), Dim::Fixed(3)],
    );
    if s.opacity {
        g.output(OUTPUT_OPACITY, DataType::Float, &[rays, Dim::Fixed(1)]);
    }
    let n_values = g.n_initializer_values();
    let doc = format!(
        "NLDF student: {} x {} residual MLP over beams of K = {} points with L = {} \
         frequencies and a {}-d audio code, M = {} segments. Inputs {INPUT_ORIGINS} and \
         {INPUT_DIRECTIONS} [{RAY_AXIS}, 3], {INPUT_AUDIO} [{}, {}, {}]; outputs {OUTPUT_RGB} \
         [{RAY_AXIS}, 3] and {OUTPUT_SEGMENTS} [{RAY_AXIS}, {}, 3].{}",
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
        if s.opacity {
            format!(
                " With opacity: input {INPUT_BACKGROUND} [{RAY_AXIS}, 3], output \
                 {OUTPUT_OPACITY} [{RAY_AXIS}, 1], and {OUTPUT_RGB} = sum of the segments \
                 + (1 - {OUTPUT_OPACITY}) {INPUT_BACKGROUND}."
            )
        } else {
            String::new()
        },
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
    metadata: Vec<crate::onnx::StringStringEntryProto>,
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
/// [`OUTPUT_RGB`], [`OUTPUT_SEGMENTS`] and, for a model with opacity (which needs
/// `background`), [`OUTPUT_OPACITY`]; the caller declares which are graph outputs.
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

/// Beam encoding: points `x_k = o + t_k d` at the K evenly spaced `t_k` of
/// `BeamSpec::t_value`, flattened to `[x_0, y_0, z_0, x_1, ...]`, clamped to
/// `±MAX_COORD`, then `[x | sin(2^0 x) | cos(2^0 x) | ... | cos(2^(L-1) x)]`, the octaves
/// above the first by the double-angle identities in f64, as `nldf_core::encoding` computes
/// them.
///
/// # Shapes
/// - `origins`, `directions`: `[n_rays, 3]`
/// - returns `beam.encoded` `[n_rays, 3 K (1 + 2 L)]`
fn encode_beams(
    g: &mut GraphBuilder,
    ckpt: &StudentCheckpoint,
    origins: &str,
    directions: &str,
) -> String {
    let beam = ckpt.shape.beam;
    let (near, far) = (ckpt.spec.near, ckpt.spec.far);
    let (k, l) = (beam.n_points, beam.n_freqs);
    let (origins, directions) = match &beam.anchor {
        Some(anchor) => anchor_rays(g, anchor, origins, directions),
        None => (origins.to_string(), directions.to_string()),
    };
    let t: Vec<f32> = (0..k).map(|i| beam.t_value(i, near, far, 0.0)).collect();
    let t = g.constant_f32("beam.t_vals", &[1, k, 1], &t);
    let axis1 = g.constant_i64("beam.axis1", &[1], &[1]);
    let o = g.node("Unsqueeze", "beam.origins", &[&origins, &axis1], vec![]);
    let d = g.node(
        "Unsqueeze",
        "beam.directions",
        &[&directions, &axis1],
        vec![],
    );
    let td = g.node("Mul", "beam.offsets", &[&d, &t], vec![]);
    let points = g.node("Add", "beam.points3", &[&o, &td], vec![]);
    let flat_shape = g.constant_i64("beam.flat_shape", &[2], &[0, 3 * k as i64]);
    let flat = g.node(
        "Reshape",
        "beam.points_flat",
        &[&points, &flat_shape],
        vec![],
    );
    let lo = g.constant_f32("beam.min_coord", &[], &[-MAX_COORD]);
    let hi = g.constant_f32("beam.max_coord", &[], &[MAX_COORD]);
    let x = g.node("Clip", "beam.points", &[&flat, &lo, &hi], vec![]);
    if l == 0 {
        return g.node("Identity", "beam.encoded", &[&x], vec![]);
    }
    // As `nldf_core::encoding` computes it, op for op: sin and cos at the lowest octave,
    // then the double-angle identities of `nldf_core::encoding::double_angle`, all in
    // double precision, rounded to f32 once. 2 transcendental ops per value instead of 2 L
    // (runtimes without vectorised Sin/Cos spend most of a frame there), and the f64 climb
    // keeps each value within an f32 rounding of the exact sine.
    let double = DataType::Double as i64;
    let xd = g.node(
        "Cast",
        "beam.points_f64",
        &[&x],
        vec![attr_int("to", double)],
    );
    let mut blocks = vec![xd.clone()];
    let mut s = g.node("Sin", "beam.sin0", &[&xd], vec![]);
    let mut c = g.node("Cos", "beam.cos0", &[&xd], vec![]);
    blocks.push(s.clone());
    blocks.push(c.clone());
    for octave in 1..l {
        let p = g.node("Mul", &format!("beam.sc{octave}"), &[&s, &c], vec![]);
        let diff = g.node("Sub", &format!("beam.c_minus_s{octave}"), &[&c, &s], vec![]);
        let sum = g.node("Add", &format!("beam.c_plus_s{octave}"), &[&c, &s], vec![]);
        s = g.node("Add", &format!("beam.sin{octave}"), &[&p, &p], vec![]);
        c = g.node("Mul", &format!("beam.cos{octave}"), &[&diff, &sum], vec![]);
        blocks.push(s.clone());
        blocks.push(c.clone());
    }
    // Each block rounded to f32 before they are joined: the same values as rounding the
    // joined f64 features, with half the bytes to copy.
    let blocks: Vec<String> = blocks
        .iter()
        .enumerate()
        .map(|(b, block)| {
            g.node(
                "Cast",
                &format!("beam.block{b}_f32"),
                &[block],
                vec![attr_int("to", DataType::Float as i64)],
            )
        })
        .collect();
    let refs: Vec<&str> = blocks.iter().map(String::as_str).collect();
    let encoded = g.node("Concat", "beam.concat", &refs, vec![attr_int("axis", 1)]);
    // The same clamp once more, a no-op on these values, keeps the features one tensor:
    // tract splits a product whose input is a feature-axis Concat into one small product
    // per block (21 for L = 10), several times slower than the single product.
    g.node("Clip", "beam.encoded", &[&encoded, &lo, &hi], vec![])
}

/// The anchored rays of `nldf_core::beam::BeamAnchor::apply`, op for op in f64 and rounded
/// to f32 once: `u = d / max(|d|, MIN_DIRECTION_LENGTH)`, `s = (centre - o) . u`,
/// `o' = o + (s - distance) u`. Dot products add their terms x, y, z in that order, as
/// glam does, so that the graph and the trainer agree to the bit on common inputs.
///
/// # Shapes
/// - `origins`, `directions`: `[n_rays, 3]`; returns the anchored pair, `[n_rays, 3]` each
fn anchor_rays(
    g: &mut GraphBuilder,
    anchor: &BeamAnchor,
    origins: &str,
    directions: &str,
) -> (String, String) {
    let double = attr_int("to", DataType::Double as i64);
    let float = attr_int("to", DataType::Float as i64);
    let o = g.node("Cast", "anchor.o", &[origins], vec![double.clone()]);
    let d = g.node("Cast", "anchor.d", &[directions], vec![double.clone()]);
    let axis = g.constant_i64("anchor.axis", &[1], &[1]);
    let bounds: Vec<(String, String)> = (0..3)
        .map(|c| {
            (
                g.constant_i64(&format!("anchor.start{c}"), &[1], &[c]),
                g.constant_i64(&format!("anchor.end{c}"), &[1], &[c + 1]),
            )
        })
        .collect();
    // `a . b` per ray, `[n_rays, 1]`: ((a_x b_x + a_y b_y) + a_z b_z).
    let dot = |g: &mut GraphBuilder, name: &str, a: &str, b: &str| -> String {
        let p = g.node("Mul", &format!("anchor.{name}.products"), &[a, b], vec![]);
        let terms: Vec<String> = bounds
            .iter()
            .enumerate()
            .map(|(c, (start, end))| {
                g.node(
                    "Slice",
                    &format!("anchor.{name}.term{c}"),
                    &[&p, start, end, &axis],
                    vec![],
                )
            })
            .collect();
        let xy = g.node(
            "Add",
            &format!("anchor.{name}.xy"),
            &[&terms[0], &terms[1]],
            vec![],
        );
        g.node("Add", &format!("anchor.{name}"), &[&xy, &terms[2]], vec![])
    };
    let len2 = dot(g, "length2", &d, &d);
    let len = g.node("Sqrt", "anchor.length_raw", &[&len2], vec![]);
    let min = g.constant_f32("anchor.min_length_f32", &[], &[MIN_DIRECTION_LENGTH]);
    let min = g.node("Cast", "anchor.min_length", &[&min], vec![double.clone()]);
    let len = g.node("Max", "anchor.length", &[&len, &min], vec![]);
    let u = g.node("Div", "anchor.u", &[&d, &len], vec![]);
    let centre = g.constant_f32("anchor.centre_f32", &[1, 3], &anchor.centre);
    let centre = g.node("Cast", "anchor.centre", &[&centre], vec![double.clone()]);
    let to_centre = g.node("Sub", "anchor.to_centre", &[&centre, &o], vec![]);
    let s = dot(g, "closest", &to_centre, &u);
    let distance = g.constant_f32("anchor.distance_f32", &[], &[anchor.distance]);
    let distance = g.node("Cast", "anchor.distance", &[&distance], vec![double]);
    let shift = g.node("Sub", "anchor.shift", &[&s, &distance], vec![]);
    let step = g.node("Mul", "anchor.step", &[&shift, &u], vec![]);
    let origin = g.node("Add", "anchor.origin_f64", &[&o, &step], vec![]);
    let origin = g.node("Cast", "anchor.origin", &[&origin], vec![float.clone()]);
    let u = g.node("Cast", "anchor.direction", &[&u], vec![float]);
    (origin, u)
}

/// `x W^T + b` with the checkpoint's Linear `name` for a product every ray passes through:
/// in int8 under [`WeightType::Int8`] ([`GraphBuilder::matmul_int8`]), else as [`linear`].
fn ray_linear(
    g: &mut GraphBuilder,
    ckpt: &StudentCheckpoint,
    name: &str,
    x: &str,
    in_dim: usize,
    out_dim: usize,
) -> Result<String> {
    g.tap(name, x, in_dim);
    if g.weight_type() != WeightType::Int8 {
        return linear(g, ckpt, name, x, in_dim, out_dim);
    }
    let w = ckpt.weight(&format!("{name}.weight"), &[out_dim, in_dim])?;
    let b = ckpt.weight(&format!("{name}.bias"), &[out_dim])?;
    let product = g
        .matmul_int8(name, x, w, out_dim, in_dim)
        .map_err(Error::Calibration)?;
    let b = g.weight(&format!("{name}.bias"), &[out_dim], b);
    Ok(g.node("Add", name, &[&product, &b], vec![]))
}

/// `x W^T + b` with the checkpoint's Linear `name` (`weight` `[out, in]`, `bias` `[out]`).
fn linear(
    g: &mut GraphBuilder,
    ckpt: &StudentCheckpoint,
    name: &str,
    x: &str,
    in_dim: usize,
    out_dim: usize,
) -> Result<String> {
    let w = ckpt.weight(&format!("{name}.weight"), &[out_dim, in_dim])?;
    let b = ckpt.weight(&format!("{name}.bias"), &[out_dim])?;
    let w = g.weight(&format!("{name}.weight"), &[out_dim, in_dim], w);
    let b = g.weight(&format!("{name}.bias"), &[out_dim], b);
    Ok(g.node("Gemm", name, &[x, &w, &b], vec![attr_int("transB", 1)]))
}

/// The checkpoint's Conv1d `name` (`weight` `[out, in, 3]`, padding 1) followed by
/// LeakyReLU 0.02.
fn conv_leaky(
    g: &mut GraphBuilder,
    ckpt: &StudentCheckpoint,
    name: &str,
    x: &str,
    (in_dim, out_dim, stride): (usize, usize, usize),
) -> Result<String> {
    let w = ckpt.weight(&format!("{name}.weight"), &[out_dim, in_dim, 3])?;
    let b = ckpt.weight(&format!("{name}.bias"), &[out_dim])?;
    let w = g.weight(&format!("{name}.weight"), &[out_dim, in_dim, 3], w);
    let b = g.weight(&format!("{name}.bias"), &[out_dim], b);
    let y = g.node(
        "Conv",
        name,
        &[x, &w, &b],
        vec![
            attr_ints("kernel_shape", &[3]),
            attr_ints("strides", &[stride as i64]),
            attr_ints("pads", &[1, 1]),
            attr_ints("dilations", &[1]),
            attr_int("group", 1),
        ],
    );
    Ok(leaky(g, &format!("{name}.act"), &y))
}

fn leaky(g: &mut GraphBuilder, name: &str, x: &str) -> String {
    g.node("LeakyRelu", name, &[x], vec![attr_float("alpha", SLOPE)])
}

/// The audio code of the frame: AudioNet over each window of the neighbourhood and
/// AudioAttNet's weighted sum, or AudioNet over the centre window without attention.
///
/// # Shapes
/// - `audio`: `[att_frames, window, n_features]`
/// - returns `audio.code` `[1, dim]`
fn audio_code(g: &mut GraphBuilder, ckpt: &StudentCheckpoint, audio: &str) -> Result<String> {
    let a = &ckpt.shape.audio;
    let seq = a.att_frames;
    let windows = if ckpt.shape.attention {
        audio.to_string()
    } else {
        let c = (seq / 2) as i64;
        let starts = g.constant_i64("audio.centre_start", &[1], &[c]);
        let ends = g.constant_i64("audio.centre_end", &[1], &[c + 1]);
        let axes = g.constant_i64("audio.centre_axis", &[1], &[0]);
        g.node(
            "Slice",
            "audio.centre",
            &[audio, &starts, &ends, &axes],
            vec![],
        )
    };
    // AudioNet: [n, window, F] -> [n, F, window] -> convs -> mean over what is left.
    let mut x = g.node(
        "Transpose",
        "audio.net.input",
        &[&windows],
        vec![attr_ints("perm", &[0, 2, 1])],
    );
    let channels = [a.n_features, 32, 32, 64, 64];
    for i in 0..4 {
        let name = format!("audio.net.convs.{i}");
        x = conv_leaky(g, ckpt, &name, &x, (channels[i], channels[i + 1], 2))?;
    }
    let x = g.node(
        "ReduceMean",
        "audio.net.mean",
        &[&x],
        vec![attr_ints("axes", &[2]), attr_int("keepdims", 0)],
    );
    let x = linear(g, ckpt, "audio.net.fc1", &x, 64, 64)?;
    let x = leaky(g, "audio.net.fc1.act", &x);
    let codes = linear(g, ckpt, "audio.net.fc2", &x, 64, a.dim)?;
    if !ckpt.shape.attention {
        return Ok(g.node("Identity", "audio.code", &[&codes], vec![]));
    }
    // AudioAttNet: [seq, dim] -> [1, dim, seq] -> convs -> [1, seq] logits -> softmax.
    let t = g.node(
        "Transpose",
        "audio.att.input_t",
        &[&codes],
        vec![attr_ints("perm", &[1, 0])],
    );
    let axis0 = g.constant_i64("audio.att.axis0", &[1], &[0]);
    let mut y = g.node("Unsqueeze", "audio.att.input", &[&t, &axis0], vec![]);
    let channels = [a.dim, 16, 8, 4, 2, 1];
    for i in 0..5 {
        let name = format!("audio.att.convs.{i}");
        y = conv_leaky(g, ckpt, &name, &y, (channels[i], channels[i + 1], 1))?;
    }
    let shape = g.constant_i64("audio.att.logit_shape", &[2], &[1, seq as i64]);
    let y = g.node("Reshape", "audio.att.logits_in", &[&y, &shape], vec![]);
    let y = linear(g, ckpt, "audio.att.attention", &y, seq, seq)?;
    let weights = g.node(
        "Softmax",
        "audio.att.weights",
        &[&y],
        vec![attr_int("axis", 1)],
    );
    Ok(g.node("MatMul", "audio.code", &[&weights, &codes], vec![]))
}

/// The residual MLP on `[beam | code]` and the segment sum. The input layer's weight is
/// split by columns into its beam part and its audio part, so that the audio term is
/// computed once per frame and broadcast over the rays instead of concatenating the code
/// to every beam. Produces the graph outputs.
///
/// # Shapes
/// - `beams`: `[n_rays, 3 K (1 + 2 L)]`; `code`: `[1, dim]`; `background` `[n_rays, 3]`
///   (models with opacity)
/// - outputs `segments` `[n_rays, M, 3]`, `rgb` `[n_rays, 3]` and, with `background`,
///   `opacity` `[n_rays, 1]`
fn residual_mlp(
    g: &mut GraphBuilder,
    ckpt: &StudentCheckpoint,
    beams: &str,
    code: &str,
    background: Option<&str>,
) -> Result<()> {
    let s = &ckpt.shape;
    let w = s.width;
    let beam_dim = s.beam.encoded_len();
    let in_dim = beam_dim + s.audio.dim;
    let weight = ckpt.weight("mlp.input.weight", &[w, in_dim])?;
    let bias = ckpt.weight("mlp.input.bias", &[w])?;
    let (mut w_beam, mut w_code) = (
        Vec::with_capacity(w * beam_dim),
        Vec::with_capacity(w * s.audio.dim),
    );
    for row in weight.chunks_exact(in_dim) {
        w_beam.extend_from_slice(&row[..beam_dim]);
        w_code.extend_from_slice(&row[beam_dim..]);
    }
    let w_code = g.weight("mlp.input.weight.audio", &[w, s.audio.dim], &w_code);
    let bias = g.weight("mlp.input.bias", &[w], bias);
    let audio_term = g.node(
        "Gemm",
        "mlp.input.audio",
        &[code, &w_code, &bias],
        vec![attr_int("transB", 1)],
    );
    g.tap("mlp.input.beam", beams, beam_dim);
    let x = if g.weight_type() == WeightType::Int8 {
        let product = g
            .matmul_int8("mlp.input.beam", beams, &w_beam, w, beam_dim)
            .map_err(Error::Calibration)?;
        g.node("Add", "mlp.input", &[&product, &audio_term], vec![])
    } else {
        let w_beam = g.weight("mlp.input.weight.beam", &[w, beam_dim], &w_beam);
        g.node(
            "Gemm",
            "mlp.input",
            &[beams, &w_beam, &audio_term],
            vec![attr_int("transB", 1)],
        )
    };
    let mut h = g.node("Relu", "mlp.input.act", &[&x], vec![]);
    for i in 0..s.n_blocks() {
        let p = format!("mlp.body.{i}");
        let y = ray_linear(g, ckpt, &format!("{p}.fc1"), &h, w, w)?;
        let y = g.node("Relu", &format!("{p}.fc1.act"), &[&y], vec![]);
        let y = ray_linear(g, ckpt, &format!("{p}.fc2"), &y, w, w)?;
        let sum = g.node("Add", &format!("{p}.skip"), &[&h, &y], vec![]);
        h = g.node("Relu", &format!("{p}.act"), &[&sum], vec![]);
    }
    // The output layer stays in f32 under int8: its 3 M outputs are the colours
    // themselves, and it costs a twentieth of a hidden layer.
    let out = linear(g, ckpt, "mlp.output", &h, w, s.output_dim())?;
    let colours = if s.opacity {
        let axis = g.constant_i64("mlp.output_axis", &[1], &[1]);
        let slice = |g: &mut GraphBuilder, name: &str, lo: usize, hi: usize| {
            let lo = g.constant_i64(&format!("{name}.start"), &[1], &[lo as i64]);
            let hi = g.constant_i64(&format!("{name}.end"), &[1], &[hi as i64]);
            g.node("Slice", name, &[&out, &lo, &hi, &axis], vec![])
        };
        let m3 = 3 * s.segments;
        let logit = slice(g, "mlp.opacity_logit", m3, m3 + 1);
        let alpha = g.node("Sigmoid", OUTPUT_OPACITY, &[&logit], vec![]);
        // Premultiplied: a ray the head does not cover adds no colour.
        let raw = slice(g, "mlp.colours", 0, m3);
        g.node("Mul", "mlp.premultiplied", &[&raw, &alpha], vec![])
    } else {
        out
    };
    let shape = g.constant_i64("mlp.segment_shape", &[3], &[0, s.segments as i64, 3]);
    let segments = g.node("Reshape", OUTPUT_SEGMENTS, &[&colours, &shape], vec![]);
    let axis1 = g.constant_i64("mlp.segment_axis", &[1], &[1]);
    let rgb_name = if background.is_some() {
        "mlp.colour"
    } else {
        OUTPUT_RGB
    };
    let colour = g.node(
        "ReduceSum",
        rgb_name,
        &[&segments, &axis1],
        vec![attr_int("keepdims", 0)],
    );
    if let Some(background) = background {
        // rgb = colour + (1 - opacity) background: the teacher's compositing.
        let one = g.constant_f32("mlp.one", &[1], &[1.0]);
        let clear = g.node("Sub", "mlp.clear", &[&one, OUTPUT_OPACITY], vec![]);
        let behind = g.node("Mul", "mlp.behind", &[&clear, background], vec![]);
        g.node("Add", OUTPUT_RGB, &[&colour, &behind], vec![]);
    }
    Ok(())
}
