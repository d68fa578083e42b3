//! The frame graph: one ONNX file that turns a frame's audio samples and a camera pose into
//! the frame, from standard ops alone, so that any ONNX runtime renders the talking head
//! without rebuilding what nldf does around the ray graph:
//!
//! 1. the log-mel front end (`nldf_core::audio::log_mel`): framing by Gather, the Hann
//!    window, the DFT as two products with cosine and sine tables, the mel filters as a
//!    product, the log; then the windows and the neighbourhood, clamped to the track where
//!    the input marks samples off it with NaN (`nldf_core::frame_audio::FrameAudio`);
//! 2. the camera rays of AD-NeRF's `get_rays` from the intrinsics, as glam computes them;
//! 3. the head-bounds test of `nldf_core::bounds::Bounds::intersect`, and only the rays that
//!    meet the head and whose pixel the `keep` input marks go on (And, NonZero, Gather): a
//!    caller that already has a frame's other pixels (`nldf_infer::still`'s skipping) sends
//!    only the ones it wants through the student;
//! 4. the student ([`crate::student`]);
//! 5. the composite: the student's colours scattered into the background image (ScatterND),
//!    through its opacity when it has one. A pixel not kept shows the background, as one
//!    whose ray misses the head does; the `n_rays` output counts the rays that went through
//!    the student.
//!
//! The ray graph stays what nldf's own renderer and streaming run.

mod front_end;
mod mouth_patch;
mod select;

use std::path::Path;

use nldf_core::audio::FeatureConfig;
use nldf_core::frame_audio::FrameAudio;
use nldf_model::contract::{
    self, FRAME_INPUT_AUDIO, FRAME_INPUT_KEEP, FRAME_INPUT_POSE, FRAME_OUTPUT_IMAGE,
    FRAME_OUTPUT_RAYS, FRAME_OUTPUT_WINDOWS, OUTPUT_RGB,
};
use nldf_model::onnx::{DataType, ModelProto};

use crate::checkpoint::StudentCheckpoint;
use crate::error::{Error, Result};
use crate::graph::{ActivationRanges, Dim, GraphBuilder, WeightType, attr_int};
use crate::student::{ExportReport, model_info, model_proto, student_nodes, write_model};
use crate::upsampler_graph::{UpsamplerCheckpoint, upsampled_image};
use nldf_core::camera::Intrinsics;
use nldf_core::upsampler_config::coarse_intrinsics;

use crate::layers::rank_rows;
use front_end::front_end;
use mouth_patch::MouthPatch;
use select::{hit_rays, mask_indices, pixel_coords, pose_columns, ray_directions, slab_hits};

/// Name of the frame graph.
pub const FRAME_GRAPH_NAME: &str = "nldf_frame";

/// Exports the student in `student_dir` as a frame graph to `out` (written atomically),
/// with weights stored as `weights` ([`WeightType::Int8`] needs calibrated ranges: see
/// [`export_frame_int8`]).
pub fn export_frame(student_dir: &Path, out: &Path, weights: WeightType) -> Result<ExportReport> {
    if weights == WeightType::Int8 {
        return Err(crate::student::needs_ranges("--frame "));
    }
    let ckpt = StudentCheckpoint::open(student_dir)?;
    crate::student::check_f16_range(&ckpt, student_dir, weights)?;
    let (model, report_info, n_values) = frame_model(&ckpt, None, GraphBuilder::new(weights))?;
    write_model(&model, report_info, n_values, out)
}

/// Exports the student in `student_dir` with the learned upsampler in `upsampler_dir` as a
/// frame graph to `out` (written atomically): the student runs on the upsampler's coarse
/// grid and the CNN makes the full-size frame ([`crate::upsample`]).
pub fn export_frame_upsampled(
    student_dir: &Path,
    upsampler_dir: &Path,
    out: &Path,
    weights: WeightType,
) -> Result<ExportReport> {
    let paths = (student_dir, upsampler_dir, out);
    let build = |ckpt: &_, up: &_, g| frame_model(ckpt, Some(up), g);
    crate::upsampler_graph::export_pair(paths, weights, "--frame --upsampler NAME ", build)
}

/// [`export_frame_upsampled`] with the student's per-ray products in int8 over the
/// calibrated `ranges` (the ray graph's); the upsampler's convolutions stay in f32.
pub fn export_frame_upsampled_int8(
    student_dir: &Path,
    upsampler_dir: &Path,
    out: &Path,
    ranges: &ActivationRanges,
) -> Result<ExportReport> {
    let (ckpt, up) =
        crate::upsampler_graph::open_pair(student_dir, upsampler_dir, WeightType::Int8)?;
    let g = GraphBuilder::int8(ranges.clone());
    let (model, info, n_values) = frame_model(&ckpt, Some(&up), g)?;
    write_model(&model, info, n_values, out)
}

/// [`export_frame`] with int8 products whose inputs have the calibrated `ranges` (the ray
/// graph's: the products are the same).
pub fn export_frame_int8(
    student_dir: &Path,
    out: &Path,
    ranges: &ActivationRanges,
) -> Result<ExportReport> {
    let ckpt = StudentCheckpoint::open(student_dir)?;
    let (model, info, n_values) = frame_model(&ckpt, None, GraphBuilder::int8(ranges.clone()))?;
    write_model(&model, info, n_values, out)
}

/// The frame graph of `ckpt` built with `g`, its metadata and the number of values its
/// initializers hold.
fn frame_model(
    ckpt: &StudentCheckpoint,
    up: Option<&UpsamplerCheckpoint>,
    mut g: GraphBuilder,
) -> Result<(ModelProto, contract::ModelInfo, usize)> {
    let spec = &ckpt.spec;
    let (cfg, layout) = frame_audio(ckpt)?;
    let k = spec.intrinsics;
    let (h, w) = (k.height as usize, k.width as usize);
    let background = background_rgb8(ckpt, w, h)?;
    // The rays the student sees: every pixel's, or the upsampler's coarse grid's.
    let factor = up.map_or(1, |u| u.shape.factor);
    let grid = coarse_intrinsics(&k, factor).map_err(|e| Error::Frame(e.to_string()))?;
    let (hc, wc) = (grid.height as usize, grid.width as usize);

    let audio = g.input(
        FRAME_INPUT_AUDIO,
        DataType::Float,
        &[Dim::Fixed(layout.samples)],
    );
    let pose = g.input(
        FRAME_INPUT_POSE,
        DataType::Float,
        &[Dim::Fixed(4), Dim::Fixed(4)],
    );
    let keep = g.input(
        FRAME_INPUT_KEEP,
        DataType::Bool,
        &[Dim::Fixed(hc), Dim::Fixed(wc)],
    );
    let windows = front_end(&mut g, &layout, &cfg, &audio);
    let rays = camera_rays(&mut g, "rays", &grid, &pose);
    let (hits, hit, mut n_rays) = head_hits(&mut g, ckpt, &rays, &keep);
    let image = match up {
        None => composite_frame(&mut g, ckpt, &rays, &hits, &windows, &background, (h, w))?,
        Some(up) => {
            let bg = background_nodes(&mut g, &background, (h, w));
            let (o, d) = hit_rays(&mut g, "frame", &rays, &hits);
            match &up.shape.mouth_patch {
                None => {
                    student_nodes(&mut g, ckpt, (&o, &d), &windows, None)?;
                    upsampled_image(&mut g, ckpt, up, (&hits, &hit, &n_rays), &bg, (hc, wc))?
                }
                Some(mouth) => {
                    let patch = MouthPatch::rays(&mut g, ckpt, mouth, &k, &pose);
                    // One student pass over the coarse hits, then the patch's rays.
                    let axis0 = || vec![attr_int("axis", 0)];
                    let o = g.node("Concat", "patch.all_origins", &[&o, &patch.o], axis0());
                    let d = g.node("Concat", "patch.all_directions", &[&d, &patch.d], axis0());
                    student_nodes(&mut g, ckpt, (&o, &d), &windows, None)?;
                    let first = rank_rows(&mut g, "up.coarse", "keep.hit_count", &hits, None);
                    let image = crate::upsampler_graph::upsampled_image_first(
                        &mut g,
                        ckpt,
                        up,
                        &first,
                        (&hits, &hit, &n_rays),
                        &bg,
                        (hc, wc),
                    )?;
                    let all = g.node("Add", "patch.all_rays", &[&n_rays, &patch.count], vec![]);
                    let image = patch.paint(&mut g, &image, &n_rays, &bg, ckpt.shape.width, (h, w));
                    n_rays = all;
                    image
                }
            }
        }
    };
    g.node("Identity", FRAME_OUTPUT_IMAGE, &[&image], vec![]);
    g.node("Identity", FRAME_OUTPUT_WINDOWS, &[&windows], vec![]);
    g.node("Identity", FRAME_OUTPUT_RAYS, &[&n_rays], vec![]);
    frame_outputs(&mut g, ckpt, (h, w));
    let n_values = g.n_initializer_values();
    let doc = frame_doc(ckpt, &layout, up, (h, w), (hc, wc));
    let graph = g.finish(FRAME_GRAPH_NAME, &doc);
    let info = model_info(ckpt, &graph);
    let metadata = frame_metadata(&info, &layout, factor);
    Ok((model_proto(graph, doc, metadata), info, n_values))
}

/// The student's audio front end settings and the frame's audio layout; refuses a student
/// trained on another front end's features, or whose windows the features do not make.
fn frame_audio(ckpt: &StudentCheckpoint) -> Result<(FeatureConfig, FrameAudio)> {
    let spec = &ckpt.spec;
    let cfg = spec.features.nldf().cloned().ok_or_else(|| {
        Error::Frame(format!(
            "it holds nldf's audio front end, but this student was trained on {}",
            spec.features.describe()
        ))
    })?;
    let s = &ckpt.shape;
    let layout = FrameAudio::new(&cfg, spec.fps, s.audio.att_frames)
        .map_err(|e| Error::Frame(e.to_string()))?;
    if (cfg.window, cfg.n_mels) != (s.audio.window, s.audio.n_features) {
        return Err(Error::Frame(format!(
            "the features make {} x {} windows, the student takes {} x {}",
            cfg.window, cfg.n_mels, s.audio.window, s.audio.n_features
        )));
    }
    Ok((cfg, layout))
}

/// Declares the frame graph's outputs: the image, the audio windows and the ray count.
fn frame_outputs(g: &mut GraphBuilder, ckpt: &StudentCheckpoint, (h, w): (usize, usize)) {
    let s = &ckpt.shape;
    g.output(
        FRAME_OUTPUT_IMAGE,
        DataType::Float,
        &[Dim::Fixed(h), Dim::Fixed(w), Dim::Fixed(3)],
    );
    g.output(
        FRAME_OUTPUT_WINDOWS,
        DataType::Float,
        &[
            Dim::Fixed(s.audio.att_frames),
            Dim::Fixed(s.audio.window),
            Dim::Fixed(s.audio.n_features),
        ],
    );
    g.output(FRAME_OUTPUT_RAYS, DataType::Int64, &[Dim::Fixed(1)]);
}

/// The frame graph's `doc_string`: its inputs, outputs and what it does inside.
fn frame_doc(
    ckpt: &StudentCheckpoint,
    layout: &FrameAudio,
    up: Option<&UpsamplerCheckpoint>,
    (h, w): (usize, usize),
    (hc, wc): (usize, usize),
) -> String {
    let s = &ckpt.shape;
    let factor = up.map_or(1, |u| u.shape.factor);
    format!(
        "NLDF frame graph: input {FRAME_INPUT_AUDIO} [{}] (16 kHz samples from frame f's \
         sample f * {} + {}; NaN off the track), {FRAME_INPUT_POSE} [4, 4] (camera to world, \
         row-major), {FRAME_INPUT_KEEP} bool [{h}, {w}] (pixels to render; the rest show the \
         background); output {FRAME_OUTPUT_IMAGE} [{h}, {w}, 3] in [0, 1], \
         {FRAME_OUTPUT_RAYS} [1] (rays through the student). Inside: log-mel front end, rays, \
         head-bounds test and keep, student ({} x {}), composite over the background.{}",
        layout.samples,
        layout.samples_per_frame,
        layout.offset,
        s.depth,
        s.width,
        match up {
            None => String::new(),
            Some(u) => format!(
                " With a learned upsampler x{factor}: {FRAME_INPUT_KEEP} is the coarse grid's \
                 [{hc}, {wc}], the student runs on the coarse rays that meet the head and a CNN \
                 ({:?} channels) makes the frame on their box.{}",
                u.shape.channels,
                if u.shape.mouth_patch.is_some() {
                    " Mouth patch: the pixels whose rays meet the mouth's box are the student's \
                     own rays (whatever keep says; counted in n_rays)."
                } else {
                    ""
                }
            ),
        }
    )
}

/// The frame graph's metadata: the model's, and with an upsampler its factor
/// ([`contract::keys::FRAME_UPSAMPLE`]) before the background.
fn frame_metadata(
    info: &contract::ModelInfo,
    layout: &FrameAudio,
    factor: usize,
) -> Vec<nldf_model::onnx::StringStringEntryProto> {
    let mut metadata = info.to_frame_metadata(layout);
    if factor > 1 {
        let at = metadata.len().saturating_sub(1);
        metadata.insert(
            at,
            nldf_model::onnx::StringStringEntryProto {
                key: Some(nldf_model::contract::keys::FRAME_UPSAMPLE.to_string()),
                value: Some(factor.to_string()),
            },
        );
    }
    metadata
}

/// The background as 8-bit RGB at the image's size, `[h * w * 3]`.
fn background_rgb8(ckpt: &StudentCheckpoint, w: usize, h: usize) -> Result<Vec<u8>> {
    let bad = |e: String| Error::Frame(format!("the student's background image: {e}"));
    let img = image::load_from_memory(&ckpt.background_png)
        .map_err(|e| bad(e.to_string()))?
        .to_rgb8();
    if img.dimensions() != (w as u32, h as u32) {
        return Err(bad(format!(
            "{} x {}, the image is {w} x {h}",
            img.width(),
            img.height()
        )));
    }
    Ok(img.into_raw())
}

/// The camera's rays through every pixel, row by row: `(origin [1, 3], directions
/// [h w, 3])`, `d = (c0 x_i + c1 y_j) + c2 (-1)` with the rotation's columns `c` and
/// AD-NeRF's `x_i = (i - cx) / f`, `y_j = -(j - cy) / f`, added in glam's order; its nodes'
/// names start with `prefix`.
fn camera_rays(g: &mut GraphBuilder, prefix: &str, k: &Intrinsics, pose: &str) -> (String, String) {
    let (xs, ys) = pixel_coords(k);
    let xs = g.constant_f32(&format!("{prefix}.x"), &[1, k.width as usize, 1], &xs);
    let ys = g.constant_f32(&format!("{prefix}.y"), &[k.height as usize, 1, 1], &ys);
    let (columns, origin) = pose_columns(g, prefix, pose);
    (origin, ray_directions(g, prefix, &columns, (&xs, &ys)))
}

/// The pixels whose rays meet the head's bounds within `[near, far]`
/// (`Bounds::intersect`'s slab test, axis by axis) and that `keep` marks: their `[n_hit]`
/// int64 indices, row-major, their bool mask `[h w]`, and how many there are, int64 `[1]`.
///
/// # Shapes
/// - `keep`: bool `[h, w]`
fn head_hits(
    g: &mut GraphBuilder,
    ckpt: &StudentCheckpoint,
    rays: &(String, String),
    keep: &str,
) -> (String, String, String) {
    let spec = &ckpt.spec;
    let hit = slab_hits(g, "bounds", &spec.bounds, (spec.near, spec.far), rays);
    let flat = g.constant_i64("keep.flat_shape", &[1], &[-1]);
    let keep = g.node("Reshape", "keep.pixels", &[keep, &flat], vec![]);
    let hit = g.node("And", "keep.hit", &[&hit, &keep], vec![]);
    let (hits, n_hit) = mask_indices(g, ("bounds", "keep"), &hit);
    (hits, hit, n_hit)
}

/// The background image as floats in [0, 1], `[h w, 3]`.
fn background_nodes(g: &mut GraphBuilder, background: &[u8], (h, w): (usize, usize)) -> String {
    let bg = g.constant_u8("frame.background_rgb8", &[h * w, 3], background);
    let bg = g.node(
        "Cast",
        "frame.background_raw",
        &[&bg],
        vec![attr_int("to", DataType::Float as i64)],
    );
    let full = g.constant_f32("frame.full_scale", &[], &[255.0]);
    g.node("Div", "frame.background", &[&bg, &full], vec![])
}

/// The student on the rays `hits` selects, scattered into the background image.
///
/// # Shapes
/// - `rays`: origin `[1, 3]`, directions `[h w, 3]`; `hits` `[n_hit]`
/// - `windows`: `[att_frames, window, n_features]`; `background`: `[h w 3]` bytes
/// - returns `[h, w, 3]`
fn composite_frame(
    g: &mut GraphBuilder,
    ckpt: &StudentCheckpoint,
    rays: &(String, String),
    hits: &str,
    windows: &str,
    background: &[u8],
    (h, w): (usize, usize),
) -> Result<String> {
    let axis0 = || vec![attr_int("axis", 0)];
    let (o, d) = hit_rays(g, "frame", rays, hits);
    let bg = background_nodes(g, background, (h, w));
    let behind = g.node("Gather", "frame.behind", &[&bg, hits], axis0());
    student_nodes(g, ckpt, (&o, &d), windows, Some(&behind))?;
    let axis1 = g.constant_i64("frame.index_axis", &[1], &[1]);
    let at = g.node("Unsqueeze", "frame.hit_pixels", &[hits, &axis1], vec![]);
    let painted = g.node(
        "ScatterND",
        "frame.painted",
        &[&bg, &at, OUTPUT_RGB],
        vec![],
    );
    let image_shape = g.constant_i64("frame.image_shape", &[3], &[h as i64, w as i64, 3]);
    Ok(g.node("Reshape", "frame.image", &[&painted, &image_shape], vec![]))
}
