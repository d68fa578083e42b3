//! The upsampled ray graph (contract 5, and 6 with a mouth patch): the coarse rays of a box
//! of the upsampler's coarse grid in, the box's pixels out; nldf's renderer
//! (`nldf_infer::FrameRenderer`) finds the box and its rays, and the mouth patch's rays.

use std::path::Path;

use nldf_model::contract::{
    BOX_COLS, BOX_HEIGHT, BOX_ROWS, BOX_WIDTH, INPUT_AUDIO, INPUT_BACKGROUND, INPUT_CELLS,
    INPUT_DIRECTIONS, INPUT_ORIGINS, INPUT_PATCH_BACKGROUND, INPUT_PATCH_DIRECTIONS,
    INPUT_PATCH_ORIGINS, ModelInfo, OUTPUT_BOX_OPACITY, OUTPUT_BOX_RGB, OUTPUT_PATCH_RGB,
    OUTPUT_SEGMENTS, PATCH_AXIS, RAY_AXIS, UpsampleInfo,
};
use nldf_model::onnx::{DataType, ModelProto};

use crate::checkpoint::StudentCheckpoint;
use crate::error::{Error, Result};
use crate::graph::{ActivationRanges, Dim, GraphBuilder, WeightType, attr_int};
use crate::patch::{PatchInputs, patch_pixels};
use crate::student::{
    ExportReport, model_info, model_proto, ray_inputs, student_nodes, write_model,
};
use crate::upsampler_graph::{UP_ROWS, UpsamplerCheckpoint, export_pair, open_pair, upsampled_box};

/// Exports the student in `student_dir` with the learned upsampler in `upsampler_dir` as an
/// upsampled ray graph to `out` (written atomically): the coarse rays of a box of the
/// upsampler's coarse grid in, the box's pixels out ([`nldf_model::contract::UpsampleInfo`]).
/// nldf's renderer (`nldf_infer::FrameRenderer`) finds the box and its rays.
pub fn export_student_upsampled(
    student_dir: &Path,
    upsampler_dir: &Path,
    out: &Path,
    weights: WeightType,
) -> Result<ExportReport> {
    let paths = (student_dir, upsampler_dir, out);
    export_pair(paths, weights, "--upsampler NAME ", upsampled_ray_model)
}

/// [`export_student_upsampled`] with the student's per-ray products in int8, their inputs'
/// ranges calibrated (`ranges`, as for the student's own int8 ray graph); the upsampler's
/// convolutions stay in f32.
pub fn export_student_upsampled_int8(
    student_dir: &Path,
    upsampler_dir: &Path,
    out: &Path,
    ranges: &ActivationRanges,
) -> Result<ExportReport> {
    let (ckpt, up) = open_pair(student_dir, upsampler_dir, WeightType::Int8)?;
    let g = GraphBuilder::int8(ranges.clone());
    let (model, info, n_values) = upsampled_ray_model(&ckpt, &up, g)?;
    write_model(&model, info, n_values, out)
}

/// The upsampled ray graph of `ckpt` and `up` built with `g`, its metadata and the number
/// of values its initializers hold.
///
/// # Graph
/// - inputs `rays_o`, `rays_d` `[n_rays, 3]` (the box's coarse rays that meet the head, in
///   the row-major order of the true cells of `cells`), `audio`, `cells` bool
///   `[box_rows, box_cols]`, `background` `[box_height, box_width, 3]` (`r` times the
///   box's rows and columns)
/// - outputs `box_rgb` `[box_height, box_width, 3]`, `segments` `[n_rays, M, 3]` (the
///   student's premultiplied segment colours), `box_opacity` `[box_height, box_width, 1]`
/// - with a mouth patch, inputs `patch_o`, `patch_d`, `patch_background` `[n_patch, 3]`
///   and output `patch_rgb` `[n_patch, 3]` ([`patched_box`])
fn upsampled_ray_model(
    ckpt: &StudentCheckpoint,
    up: &UpsamplerCheckpoint,
    mut g: GraphBuilder,
) -> Result<(ModelProto, ModelInfo, usize)> {
    let s = &ckpt.shape;
    let r = up.shape.factor;
    nldf_core::upsampler_config::coarse_intrinsics(&ckpt.spec.intrinsics, r)
        .map_err(|e| Error::Frame(e.to_string()))?;
    let sym = |name: &str| Dim::Symbolic(name.to_string());
    let rays = sym(RAY_AXIS);
    let (origins, directions, audio) = ray_inputs(&mut g, ckpt);
    let cells = g.input(INPUT_CELLS, DataType::Bool, &[sym(BOX_ROWS), sym(BOX_COLS)]);
    let pixels = [sym(BOX_HEIGHT), sym(BOX_WIDTH)];
    let background = g.input(
        INPUT_BACKGROUND,
        DataType::Float,
        &[pixels[0].clone(), pixels[1].clone(), Dim::Fixed(3)],
    );
    let patch = up.shape.mouth_patch.map(|_| PatchInputs::declare(&mut g));
    let (rgb, alpha) = match &patch {
        None => {
            student_nodes(&mut g, ckpt, (&origins, &directions), &audio, None)?;
            upsampled_box(&mut g, ckpt, up, &cells, &background, None)?
        }
        Some(p) => patched_box(
            &mut g,
            (ckpt, up),
            (&origins, &directions),
            &audio,
            p,
            (&cells, &background),
        )?,
    };
    g.node("Identity", OUTPUT_BOX_RGB, &[&rgb], vec![]);
    g.node("Identity", OUTPUT_BOX_OPACITY, &[&alpha], vec![]);
    g.output(
        OUTPUT_BOX_RGB,
        DataType::Float,
        &[pixels[0].clone(), pixels[1].clone(), Dim::Fixed(3)],
    );
    g.output(
        OUTPUT_SEGMENTS,
        DataType::Float,
        &[rays, Dim::Fixed(s.segments), Dim::Fixed(3)],
    );
    g.output(
        OUTPUT_BOX_OPACITY,
        DataType::Float,
        &[pixels[0].clone(), pixels[1].clone(), Dim::Fixed(1)],
    );
    if patch.is_some() {
        g.output(
            OUTPUT_PATCH_RGB,
            DataType::Float,
            &[sym(PATCH_AXIS), Dim::Fixed(3)],
        );
    }
    let n_values = g.n_initializer_values();
    let doc = ray_graph_doc(ckpt, up);
    let graph = g.finish(nldf_model::contract::GRAPH_NAME, &doc);
    let mut info = model_info(ckpt, &graph);
    info.upsample = Some(UpsampleInfo {
        factor: r,
        margin: up.shape.margin,
        mouth_patch: up.shape.mouth_patch,
    });
    let metadata = info.to_metadata();
    Ok((model_proto(graph, doc, metadata), info, n_values))
}

/// The student on the coarse rays and then the mouth patch's (`p`) in one pass, the box
/// from the coarse rays' rows, [`OUTPUT_SEGMENTS`] the coarse rays' and [`OUTPUT_PATCH_RGB`]
/// the patch's pixels: the box's pixels and opacity, as [`upsampled_box`].
fn patched_box(
    g: &mut GraphBuilder,
    (ckpt, up): (&StudentCheckpoint, &UpsamplerCheckpoint),
    (origins, directions): (&str, &str),
    audio: &str,
    p: &PatchInputs,
    (cells, background): (&str, &str),
) -> Result<(String, String)> {
    let axis0 = || vec![attr_int("axis", 0)];
    let o = g.node("Concat", "patch.all_origins", &[origins, &p.o], axis0());
    let d = g.node(
        "Concat",
        "patch.all_directions",
        &[directions, &p.d],
        axis0(),
    );
    student_nodes(g, ckpt, (&o, &d), audio, None)?;
    let (first, at) = p.rows(g, cells);
    // The segments output keeps the coarse rays' rows.
    g.rename(OUTPUT_SEGMENTS, "patch.all_segments");
    g.node(
        "Gather",
        OUTPUT_SEGMENTS,
        &["patch.all_segments", &first],
        axis0(),
    );
    let out = upsampled_box(g, ckpt, up, cells, background, Some(&first))?;
    let pixels = patch_pixels(g, "patch", (UP_ROWS, &at), &p.background, ckpt.shape.width);
    g.node("Identity", OUTPUT_PATCH_RGB, &[&pixels], vec![]);
    Ok(out)
}

/// The upsampled ray graph's doc string.
fn ray_graph_doc(ckpt: &StudentCheckpoint, up: &UpsamplerCheckpoint) -> String {
    let s = &ckpt.shape;
    let r = up.shape.factor;
    let patch = if up.shape.mouth_patch.is_some() {
        format!(
            " Mouth patch: inputs {INPUT_PATCH_ORIGINS} and {INPUT_PATCH_DIRECTIONS} \
             [{PATCH_AXIS}, 3] (the rays of the output pixels whose rays meet the mouth's \
             box, nldf.upsample's mouth_patch) and {INPUT_PATCH_BACKGROUND} [{PATCH_AXIS}, \
             3]; output {OUTPUT_PATCH_RGB} [{PATCH_AXIS}, 3], the student's own colours \
             of those rays composited over their background."
        )
    } else {
        String::new()
    };
    format!(
        "NLDF student ({} x {}) with a learned upsampler x{r} ({:?} channels): inputs \
         {INPUT_ORIGINS} and {INPUT_DIRECTIONS} [{RAY_AXIS}, 3] (the coarse rays of a box of \
         the coarse grid that meet the head, in row-major order), {INPUT_AUDIO}, \
         {INPUT_CELLS} bool [{BOX_ROWS}, {BOX_COLS}] (the box; true where a ray is given), \
         {INPUT_BACKGROUND} [{BOX_HEIGHT}, {BOX_WIDTH}, 3] ({r} x the box's rows and \
         columns); outputs {OUTPUT_BOX_RGB} [{BOX_HEIGHT}, {BOX_WIDTH}, 3], the box's pixels \
         composited over the background, {OUTPUT_SEGMENTS} [{RAY_AXIS}, {}, 3] and \
         {OUTPUT_BOX_OPACITY} [{BOX_HEIGHT}, {BOX_WIDTH}, 1].{patch}",
        s.depth, s.width, up.shape.channels, s.segments,
    )
}
