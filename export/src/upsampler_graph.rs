//! The learned upsampler in the frame graph and the ray graph: the student runs on the
//! coarse grid's rays that meet the head, its last hidden layer, colour and opacity logit
//! are scattered into a canvas of the grid, the CNN runs on the box around the hits, and
//! its pixels are composited over the background inside the box, as
//! `nldf_train::upsampler` renders. The frame graph finds the box itself (below); the ray
//! graph is given it (`cells`) with the box's rays:
//!
//! ```text
//! canvas [hc wc, width + 4]     misses: zeros, then [0, 0, 0, MISS_LOGIT]
//! box    rows/cols holding a hit, widened by the margin (1 x 1 at the origin without hits)
//! x      Gather(canvas) -> [1, width + 4, bh, bw]
//! reduce Conv 1x1, Relu; stages: Conv 3x3, depth-to-space 2 (DCR), Relu; head: Conv 3x3
//! base   bilinear(colour, logit) (ConvTranspose: stride r, kernel 2r, pads r/2)
//! out    colour: base + sigmoid(base logit) head colour; logit: base + head
//!
//! The box is cut by index lists (NonZero, then Gather), not by a Slice of computed bounds:
//! tract sizes a NonZero's output when the graph runs, a Slice of computed bounds not.
//! pixel  c + (1 - sigmoid(logit)) background; the background alone without hits
//! ```

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use nldf_core::run_files::{CONFIG_FILE, MODEL_FILE};
use nldf_core::student_network::MlpLayout;
use nldf_core::upsampler_config::{Conv2dLayer, MISS_LOGIT, UpsamplerConfig};
use nldf_model::contract::{ModelInfo, OUTPUT_RGB};
use nldf_model::onnx::{DataType, ModelProto};

use crate::checkpoint::{StudentCheckpoint, Weight, checked_weight, parse_weights_of};
use crate::error::{Error, Result};
use crate::graph::{GraphBuilder, WeightType, attr_int, attr_ints};
use crate::layers::{self, bilinear_up, channels_of, depth_to_space, index_range, span};
use crate::student::ExportReport;

/// An upsampler folder, read and checked.
#[derive(Debug, Clone)]
pub struct UpsamplerCheckpoint {
    pub dir: PathBuf,
    pub shape: UpsamplerConfig,
    /// The student's folder name in the run.
    pub student: String,
    pub step: u64,
    weights: HashMap<String, Weight>,
}

impl UpsamplerCheckpoint {
    /// Reads `dir` (`config.json`: `model` and `student`; `model.safetensors`).
    pub fn open(dir: &Path) -> Result<UpsamplerCheckpoint> {
        let config_path = dir.join(CONFIG_FILE);
        let config: serde_json::Value = nldf_core::files::read_json(&config_path)?;
        let bad = |what: String| Error::invalid(&config_path, what);
        let model = config
            .get("model")
            .ok_or_else(|| bad("has no `model` field (not an upsampler config?)".into()))?;
        let shape: UpsamplerConfig = serde_json::from_value(model.clone())
            .map_err(|e| bad(format!("`model` is not an upsampler config: {e}")))?;
        shape.check("model").map_err(|e| bad(e.to_string()))?;
        let student = config
            .get("student")
            .and_then(|s| s.as_str())
            .ok_or_else(|| bad("has no `student` folder name (not an upsampler config?)".into()))?
            .to_string();
        let path = dir.join(MODEL_FILE);
        let bytes = std::fs::read(&path).map_err(|e| Error::io(&path, e))?;
        let (weights, step) = parse_weights_of(&path, &bytes, "upsampler")?;
        Ok(UpsamplerCheckpoint {
            dir: dir.to_path_buf(),
            shape,
            student,
            step,
            weights,
        })
    }

    /// The weight `name`, checked to have shape `shape`.
    fn weight(&self, name: &str, shape: &[usize]) -> Result<&[f32]> {
        checked_weight(&self.weights, &self.dir, name, shape)
    }
}

/// Opens the student in `student_dir` and the upsampler in `upsampler_dir` for an export in
/// `weights`: the upsampler must have been trained over that student.
pub(crate) fn open_pair(
    student_dir: &Path,
    upsampler_dir: &Path,
    weights: WeightType,
) -> Result<(StudentCheckpoint, UpsamplerCheckpoint)> {
    let ckpt = StudentCheckpoint::open(student_dir)?;
    let up = UpsamplerCheckpoint::open(upsampler_dir)?;
    if student_dir.file_name().and_then(|n| n.to_str()) != Some(up.student.as_str()) {
        return Err(Error::Frame(format!(
            "the upsampler in {} was trained over the student `{}`, not {}",
            upsampler_dir.display(),
            up.student,
            student_dir.display()
        )));
    }
    crate::student::check_f16_range(&ckpt, student_dir, weights)?;
    Ok((ckpt, up))
}

/// A built graph: the model, its metadata and the count of stored values.
pub(crate) type Built = (ModelProto, ModelInfo, usize);

/// Exports the student in `student_dir` with the upsampler in `upsampler_dir` as the graph
/// `build` makes, to `out` (written atomically). Int8 is refused here: its activation
/// ranges come from training rays (`flags`: the command's flags that asked for it).
pub(crate) fn export_pair(
    (student_dir, upsampler_dir, out): (&Path, &Path, &Path),
    weights: WeightType,
    flags: &str,
    build: impl FnOnce(&StudentCheckpoint, &UpsamplerCheckpoint, GraphBuilder) -> Result<Built>,
) -> Result<ExportReport> {
    if weights == WeightType::Int8 {
        return Err(crate::student::needs_ranges(flags));
    }
    let (ckpt, up) = open_pair(student_dir, upsampler_dir, weights)?;
    let (model, info, n_values) = build(&ckpt, &up, GraphBuilder::new(weights))?;
    crate::student::write_model(&model, info, n_values, out)
}

/// The checkpoint's convolution of the described layer `l` (`[c_out, c_in, k, k]`),
/// zero-padded by `k / 2`.
fn conv(
    g: &mut GraphBuilder,
    up: &UpsamplerCheckpoint,
    l: &Conv2dLayer,
    x: &str,
) -> Result<String> {
    let (name, c_in, c_out, k) = (&l.name, l.c_in, l.c_out, l.kernel);
    let w = up.weight(&format!("{name}.weight"), &[c_out, c_in, k, k])?;
    let b = up.weight(&format!("{name}.bias"), &[c_out])?;
    let w = g.weight(&format!("up.{name}.weight"), &[c_out, c_in, k, k], w);
    let b = g.weight(&format!("up.{name}.bias"), &[c_out], b);
    Ok(layers::conv2d(g, &format!("up.{name}"), x, &w, &b, k))
}

/// The node of [`student_rows`]: the student's rows (hidden layer, colour, logit) of every
/// ray it ran on, which a mouth patch's painting reads after the coarse rays'.
pub(crate) const UP_ROWS: &str = "up.rows";

/// The rows the upsampler reads per coarse ray, `[n_rays, width + 4]`: the student's last
/// hidden layer, its premultiplied colour and its opacity logit. The student's nodes must
/// already be in `g` (run without a background, so that [`OUTPUT_RGB`] is its own colour).
fn student_rows(g: &mut GraphBuilder, ckpt: &StudentCheckpoint) -> Result<String> {
    let s = &ckpt.shape;
    // The last hidden layer's activation, as the MLP's builder names it.
    let layout = MlpLayout::of(s);
    let last = layout.body.last().map_or(layout.input.path(), |b| b.path());
    let hidden = format!("{last}.act");
    Ok(g.node(
        "Concat",
        UP_ROWS,
        &[&hidden, OUTPUT_RGB, "mlp.opacity_logit"],
        vec![attr_int("axis", 1)],
    ))
}

/// A coarse ray that misses the head: zero features and colour, [`MISS_LOGIT`], `[1,
/// width + 4]`.
fn miss_row(g: &mut GraphBuilder, width: usize) -> String {
    let channels = width + 4;
    let mut miss = vec![0.0f32; channels];
    miss[channels - 1] = MISS_LOGIT;
    g.constant_f32("up.miss_row", &[1, channels], &miss)
}

/// The upsampled frame: the student's hidden layer, colour and logit on the coarse rays
/// `hits` (of the `[hc, wc]` grid, with `hit` its bool mask `[hc wc]` and `n_hit` their
/// count), through the CNN on their box, composited over `background` (float `[H W, 3]`).
///
/// The student's nodes must already be in `g` (run on the hits without a background, so
/// that `OUTPUT_RGB` is its premultiplied colour).
///
/// # Shapes
/// - returns the image `[H, W, 3]`
pub(crate) fn upsampled_image(
    g: &mut GraphBuilder,
    ckpt: &StudentCheckpoint,
    up: &UpsamplerCheckpoint,
    (hits, hit, n_hit): (&str, &str, &str),
    background: &str,
    (hc, wc): (usize, usize),
) -> Result<String> {
    let rows = student_rows(g, ckpt)?;
    upsampled_image_of(g, ckpt, up, &rows, (hits, hit, n_hit), background, (hc, wc))
}

/// [`upsampled_image`] when the student also ran on other rays after the coarse hits (a
/// mouth patch's): its rows `first` (int64 `[n_hit]`) are the coarse hits'.
pub(crate) fn upsampled_image_first(
    g: &mut GraphBuilder,
    ckpt: &StudentCheckpoint,
    up: &UpsamplerCheckpoint,
    first: &str,
    (hits, hit, n_hit): (&str, &str, &str),
    background: &str,
    (hc, wc): (usize, usize),
) -> Result<String> {
    let rows = student_rows(g, ckpt)?;
    let rows = g.node(
        "Gather",
        "up.coarse_rows",
        &[&rows, first],
        vec![attr_int("axis", 0)],
    );
    upsampled_image_of(g, ckpt, up, &rows, (hits, hit, n_hit), background, (hc, wc))
}

/// [`upsampled_image`] from the coarse hits' student rows `rows` (`[n_hit, width + 4]`).
fn upsampled_image_of(
    g: &mut GraphBuilder,
    ckpt: &StudentCheckpoint,
    up: &UpsamplerCheckpoint,
    rows: &str,
    (hits, hit, n_hit): (&str, &str, &str),
    background: &str,
    (hc, wc): (usize, usize),
) -> Result<String> {
    let r = up.shape.factor;
    let (h, w) = (hc * r, wc * r);
    let canvas = coarse_canvas(g, ckpt, rows, hits, (hc, wc));
    let b = coarse_box(g, hit, n_hit, (hc, wc), up.shape.margin);
    // The box by index lists (NonZero, Gather) rather than a Slice of computed bounds:
    // runtimes size a NonZero's output when it runs, a Slice's not always.
    let rows = index_range(g, "up.box_rows", hc, &b.r0, &b.r1, 1);
    let cols = index_range(g, "up.box_cols", wc, &b.c0, &b.c1, 1);
    let x = g.node(
        "Gather",
        "up.box_band",
        &[&canvas, &rows],
        vec![attr_int("axis", 0)],
    );
    let x = g.node("Gather", "up.box", &[&x, &cols], vec![attr_int("axis", 1)]);

    // The box's background.
    let rows_px = index_range(g, "up.pixel_rows", h, &b.r0, &b.r1, r);
    let cols_px = index_range(g, "up.pixel_cols", w, &b.c0, &b.c1, r);
    let image_shape = g.constant_i64("up.image_shape", &[3], &[h as i64, w as i64, 3]);
    let bg = g.node(
        "Reshape",
        "up.background_image",
        &[background, &image_shape],
        vec![],
    );
    let bg_box = g.node(
        "Gather",
        "up.background_band",
        &[&bg, &rows_px],
        vec![attr_int("axis", 0)],
    );
    let bg_box = g.node(
        "Gather",
        "up.background_box",
        &[&bg_box, &cols_px],
        vec![attr_int("axis", 1)],
    );
    let (pixels, _) = box_pixels(g, ckpt, up, &x, &bg_box)?;
    let pixels = g.node("Where", "up.pixels", &[&b.any, &pixels, &bg_box], vec![]);
    Ok(scatter_box(g, (&rows_px, &cols_px), &b.zero, &bg, &pixels))
}

/// The coarse grid's rows: the student's rows (hidden layer, colour, logit) of the coarse
/// rays `hits` at their cells, the miss row elsewhere.
///
/// # Shapes
/// - returns `[hc, wc, width + 4]`
fn coarse_canvas(
    g: &mut GraphBuilder,
    ckpt: &StudentCheckpoint,
    rows: &str,
    hits: &str,
    (hc, wc): (usize, usize),
) -> String {
    let width = ckpt.shape.width;
    let channels = width + 4;
    let miss = miss_row(g, width);
    let canvas_shape = g.constant_i64(
        "up.canvas_shape",
        &[2],
        &[(hc * wc) as i64, channels as i64],
    );
    let canvas = g.node("Expand", "up.canvas_empty", &[&miss, &canvas_shape], vec![]);
    let axis1 = g.constant_i64("up.index_axis", &[1], &[1]);
    let at = g.node("Unsqueeze", "up.hit_rows", &[hits, &axis1], vec![]);
    let canvas = g.node("ScatterND", "up.canvas_flat", &[&canvas, &at, rows], vec![]);
    let grid_shape = g.constant_i64(
        "up.grid_shape",
        &[3],
        &[hc as i64, wc as i64, channels as i64],
    );
    g.node("Reshape", "up.canvas", &[&canvas, &grid_shape], vec![])
}

/// The hits' box on the coarse grid, grown by `margin` cells, as node names: whether any
/// ray hit (`any`, bool `[1]`), the int64 zero `[1]`, and the box's first and past-the-end
/// rows and columns (int64 `[1]`; the 1 x 1 box at the origin without hits).
struct CoarseBox {
    any: String,
    zero: String,
    r0: String,
    r1: String,
    c0: String,
    c1: String,
}

/// The [`CoarseBox`] of the hits' mask `hit` (bool `[hc wc]`) with `n_hit` hits.
fn coarse_box(
    g: &mut GraphBuilder,
    hit: &str,
    n_hit: &str,
    (hc, wc): (usize, usize),
    margin: usize,
) -> CoarseBox {
    let mask_shape = g.constant_i64("up.mask_shape", &[2], &[hc as i64, wc as i64]);
    let mask = g.node("Reshape", "up.mask", &[hit, &mask_shape], vec![]);
    let mask = g.node(
        "Cast",
        "up.mask_i64",
        &[&mask],
        vec![attr_int("to", DataType::Int64 as i64)],
    );
    let reduce = |axis: i64| vec![attr_ints("axes", &[axis]), attr_int("keepdims", 0)];
    let row_any = g.node("ReduceMax", "up.row_any", &[&mask], reduce(1));
    let col_any = g.node("ReduceMax", "up.col_any", &[&mask], reduce(0));
    let (r0, r1) = span(g, "up.box_rows", &row_any, hc, margin);
    let (c0, c1) = span(g, "up.box_cols", &col_any, wc, margin);
    let zero = g.constant_i64("up.count_zero", &[1], &[0]);
    let one_i = g.constant_i64("up.count_one", &[1], &[1]);
    let any = g.node("Greater", "up.any_hit", &[n_hit, &zero], vec![]);
    // Without hits, the 1 x 1 box at the origin (its pixels are then the background).
    let r0 = g.node("Where", "up.row0", &[&any, &r0, &zero], vec![]);
    let r1 = g.node("Where", "up.row1", &[&any, &r1, &one_i], vec![]);
    let c0 = g.node("Where", "up.col0", &[&any, &c0, &zero], vec![]);
    let c1 = g.node("Where", "up.col1", &[&any, &c1, &one_i], vec![]);
    CoarseBox {
        any,
        zero,
        r0,
        r1,
        c0,
        c1,
    }
}

/// The frame image: the box's `pixels` (`[bh, bw, 3]`) scattered into the background image
/// `bg` (`[H, W, 3]`) at the pixel rows and columns `rows_px`, `cols_px` (int64 `[bh]`,
/// `[bw]`); `zero` is the int64 zero `[1]`.
fn scatter_box(
    g: &mut GraphBuilder,
    (rows_px, cols_px): (&str, &str),
    zero: &str,
    bg: &str,
    pixels: &str,
) -> String {
    // Indices `[bh, bw, 2]` of the box's pixels.
    let axes12 = g.constant_i64("up.axes12", &[2], &[1, 2]);
    let axes02 = g.constant_i64("up.axes02", &[2], &[0, 2]);
    let rows_b = g.node("Unsqueeze", "up.rows_col", &[rows_px, &axes12], vec![]);
    let cols_b = g.node("Unsqueeze", "up.cols_row", &[cols_px, &axes02], vec![]);
    let zero_r = g.node("Mul", "up.rows_zero", &[&rows_b, zero], vec![]);
    let zero_c = g.node("Mul", "up.cols_zero", &[&cols_b, zero], vec![]);
    let rows_b = g.node("Add", "up.rows_grid", &[&rows_b, &zero_c], vec![]);
    let cols_b = g.node("Add", "up.cols_grid", &[&cols_b, &zero_r], vec![]);
    let index = g.node(
        "Concat",
        "up.pixel_index",
        &[&rows_b, &cols_b],
        vec![attr_int("axis", 2)],
    );
    g.node("ScatterND", "frame.image", &[bg, &index, pixels], vec![])
}

/// The upsampled ray graph's box: the student's rows of the given coarse rays placed at the
/// true cells of `cells` (bool `[bh, bw]`, row-major order; the other cells are misses),
/// through the CNN, composited over `background` (float `[bh r, bw r, 3]`).
///
/// The student's nodes must already be in `g`, as for [`upsampled_image`]; when it also
/// ran on other rays (a mouth patch's), `first` (int64 `[n_rays]`) says which of its rows
/// are the given coarse rays'.
///
/// # Shapes
/// - returns the box's pixels `[bh r, bw r, 3]` and opacity `[bh r, bw r, 1]`
pub(crate) fn upsampled_box(
    g: &mut GraphBuilder,
    ckpt: &StudentCheckpoint,
    up: &UpsamplerCheckpoint,
    cells: &str,
    background: &str,
    first: Option<&str>,
) -> Result<(String, String)> {
    let mut rows = student_rows(g, ckpt)?;
    if let Some(first) = first {
        rows = g.node(
            "Gather",
            "up.coarse_rows",
            &[&rows, first],
            vec![attr_int("axis", 0)],
        );
    }
    let miss = miss_row(g, ckpt.shape.width);
    // `[bh, bw, width + 4]` of misses, by broadcasting (no shape computed in the graph).
    let axis2 = g.constant_i64("up.cell_axis", &[1], &[2]);
    let cells_f = g.node(
        "Cast",
        "up.cells_f32",
        &[cells],
        vec![attr_int("to", DataType::Float as i64)],
    );
    let cells_f = g.node("Unsqueeze", "up.cells_col", &[&cells_f, &axis2], vec![]);
    let zero = g.constant_f32("up.zero", &[1], &[0.0]);
    let zeros = g.node("Mul", "up.cells_zero", &[&cells_f, &zero], vec![]);
    let canvas = g.node("Add", "up.canvas_empty", &[&zeros, &miss], vec![]);
    let at = g.node("NonZero", "up.cell_index_t", &[cells], vec![]);
    let at = g.node(
        "Transpose",
        "up.cell_index",
        &[&at],
        vec![attr_ints("perm", &[1, 0])],
    );
    let x = g.node("ScatterND", "up.box", &[&canvas, &at, &rows], vec![]);
    box_pixels(g, ckpt, up, &x, background)
}

/// The CNN on the student's box `x` (`[bh, bw, width + 4]`, channel-last) composited over
/// `background` (`[bh r, bw r, 3]`): the pixels `[bh r, bw r, 3]` and their opacity
/// `[bh r, bw r, 1]`.
fn box_pixels(
    g: &mut GraphBuilder,
    ckpt: &StudentCheckpoint,
    up: &UpsamplerCheckpoint,
    x: &str,
    background: &str,
) -> Result<(String, String)> {
    let width = ckpt.shape.width;
    let cfg = &up.shape;
    let (r, channels) = (cfg.factor, width + 4);
    let x = g.node(
        "Transpose",
        "up.box_chw",
        &[x],
        vec![attr_ints("perm", &[2, 0, 1])],
    );
    let axis0 = g.constant_i64("up.batch_axis", &[1], &[0]);
    let axis1 = g.constant_i64("up.channel_axis_chw", &[1], &[1]);
    let x = g.node("Unsqueeze", "up.input", &[&x, &axis0], vec![]);

    // The CNN.
    let layout = cfg.layout(width);
    let mut y = conv(g, up, &layout.reduce, &x)?;
    y = g.node("Relu", "up.reduce.act", &[&y], vec![]);
    for stage in &layout.stages {
        let name = &stage.name;
        y = conv(g, up, stage, &y)?;
        y = depth_to_space(g, &format!("up.{name}.shuffle"), &y, 2);
        y = g.node("Relu", &format!("up.{name}.act"), &[&y], vec![]);
    }
    let head = conv(g, up, &layout.head, &y)?;
    let base = channels_of(g, "up.base", &x, &axis1, (width as i64, channels as i64));
    let base = bilinear_up(g, "up.base_bilinear", &base, 4, r);
    let base_colour = channels_of(g, "up.base_colour", &base, &axis1, (0, 3));
    let base_logit = channels_of(g, "up.base_logit", &base, &axis1, (3, 4));
    let head_colour = channels_of(g, "up.head_colour", &head, &axis1, (0, 3));
    let head_logit = channels_of(g, "up.head_logit", &head, &axis1, (3, 4));
    // The colour's correction gated by the upsampled opacity.
    let gate = g.node("Sigmoid", "up.gate", &[&base_logit], vec![]);
    let gated = g.node(
        "Mul",
        "up.head_colour_gated",
        &[&head_colour, &gate],
        vec![],
    );
    let colour = g.node("Add", "up.colour_out", &[&base_colour, &gated], vec![]);
    let logit = g.node("Add", "up.logit_out", &[&base_logit, &head_logit], vec![]);
    let out = g.node(
        "Concat",
        "up.output",
        &[&colour, &logit],
        vec![attr_int("axis", 1)],
    );
    let out = g.node("Squeeze", "up.output_chw", &[&out, &axis0], vec![]);
    let out = g.node(
        "Transpose",
        "up.output_hwc",
        &[&out],
        vec![attr_ints("perm", &[1, 2, 0])],
    );
    let axis2 = g.constant_i64("up.channel_axis", &[1], &[2]);
    let colour = channels_of(g, "up.colour", &out, &axis2, (0, 3));
    let logit = channels_of(g, "up.logit", &out, &axis2, (3, 4));
    let alpha = g.node("Sigmoid", "up.opacity", &[&logit], vec![]);
    let one = g.constant_f32("up.one", &[1], &[1.0]);
    let clear = g.node("Sub", "up.clear", &[&one, &alpha], vec![]);
    let behind = g.node("Mul", "up.behind", &[&clear, background], vec![]);
    let pixels = g.node("Add", "up.pixels_raw", &[&colour, &behind], vec![]);
    Ok((pixels, alpha))
}
