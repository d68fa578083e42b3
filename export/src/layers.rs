//! ONNX layers the graphs share, each written once: a padded convolution, bilinear
//! upsampling as a transposed convolution with fixed weights, depth-to-space, a slice of
//! channels, and the index helpers that cut a box of hits out of a grid or pick a mask's rows.

use nldf_core::upsampler_config::bilinear_kernel;

use nldf_model::onnx::DataType;

use crate::graph::{GraphBuilder, attr_int, attr_ints};

/// A convolution of `x` with weight `w` (`[c_out, c_in, k, k]`) and bias `b` (graph names),
/// zero-padded by `k / 2`.
pub(crate) fn conv2d(
    g: &mut GraphBuilder,
    name: &str,
    x: &str,
    w: &str,
    b: &str,
    k: usize,
) -> String {
    let p = (k / 2) as i64;
    g.node(
        "Conv",
        name,
        &[x, w, b],
        vec![
            attr_ints("kernel_shape", &[k as i64, k as i64]),
            attr_ints("pads", &[p, p, p, p]),
        ],
    )
}

/// Bilinear upsampling by `r` of the `c` channels of `x` as
/// `nldf_train::upsampler::bilinear_up` computes it: a ConvTranspose of stride `r`, kernel `2
/// r` and pads `r / 2` with [`bilinear_kernel`].
pub(crate) fn bilinear_up(g: &mut GraphBuilder, name: &str, x: &str, c: usize, r: usize) -> String {
    let k = 2 * r;
    let w = bilinear_kernel(c, r);
    let w = g.constant_f32(&format!("{name}.kernel"), &[c, c, k, k], &w);
    let (r, p) = (r as i64, (r / 2) as i64);
    g.node(
        "ConvTranspose",
        name,
        &[x, &w],
        vec![
            attr_ints("kernel_shape", &[2 * r, 2 * r]),
            attr_ints("strides", &[r, r]),
            attr_ints("pads", &[p, p, p, p]),
        ],
    )
}

/// ONNX's DepthToSpace in its DCR order (`[1, r r c, h, w]` to `[1, c, h r, w r]`):
/// output channel `c` at offset `(i, j)` of each block takes input channel `(i r + j) c_count
/// + c`, as `nldf_train::upsampler::depth_to_space` computes it.
pub(crate) fn depth_to_space(g: &mut GraphBuilder, name: &str, x: &str, r: usize) -> String {
    g.node(
        "DepthToSpace",
        name,
        &[x],
        vec![
            attr_int("blocksize", r as i64),
            crate::graph::attr_string("mode", "DCR"),
        ],
    )
}

/// The first and one-past-last index of a true entry of `any` (int64 `[n]`, 0 or 1),
/// widened by `margin` within `[0, n)`: int64 `[1]` each.
pub(crate) fn span(
    g: &mut GraphBuilder,
    name: &str,
    any: &str,
    n: usize,
    margin: usize,
) -> (String, String) {
    let up: Vec<i64> = (1..=n as i64).collect();
    let down: Vec<i64> = (0..n as i64).map(|i| n as i64 - i).collect();
    let up = g.constant_i64(&format!("{name}.rank_up"), &[n], &up);
    let down = g.constant_i64(&format!("{name}.rank_down"), &[n], &down);
    let keep = || vec![attr_int("keepdims", 1)];
    let last = g.node("Mul", &format!("{name}.last_each"), &[any, &up], vec![]);
    let end = g.node("ReduceMax", &format!("{name}.end_raw"), &[&last], keep());
    let first = g.node("Mul", &format!("{name}.first_each"), &[any, &down], vec![]);
    let first = g.node(
        "ReduceMax",
        &format!("{name}.first_rank"),
        &[&first],
        keep(),
    );
    let n_c = g.constant_i64(&format!("{name}.n"), &[1], &[n as i64]);
    let start = g.node("Sub", &format!("{name}.start_raw"), &[&n_c, &first], vec![]);
    let m = g.constant_i64(&format!("{name}.margin"), &[1], &[margin as i64]);
    let zero = g.constant_i64(&format!("{name}.zero"), &[1], &[0]);
    let start = g.node("Sub", &format!("{name}.start_wide"), &[&start, &m], vec![]);
    let start = g.node("Max", &format!("{name}.start"), &[&start, &zero], vec![]);
    let end = g.node("Add", &format!("{name}.end_wide"), &[&end, &m], vec![]);
    let end = g.node("Min", &format!("{name}.end"), &[&end, &n_c], vec![]);
    (start, end)
}

/// Entries `from..to` of `x` along the axis `axis` names (an int64 `[1]` constant).
pub(crate) fn channels_of(
    g: &mut GraphBuilder,
    name: &str,
    x: &str,
    axis: &str,
    (from, to): (i64, i64),
) -> String {
    let a = g.constant_i64(&format!("{name}.start"), &[1], &[from]);
    let b = g.constant_i64(&format!("{name}.end"), &[1], &[to]);
    g.node("Slice", name, &[x, &a, &b, axis], vec![])
}

/// The indices `[k]` of `0..n` within `[start r, end r)` (`start`, `end`: int64 `[1]`).
pub(crate) fn index_range(
    g: &mut GraphBuilder,
    name: &str,
    n: usize,
    start: &str,
    end: &str,
    r: usize,
) -> String {
    let all: Vec<i64> = (0..n as i64).collect();
    let all = g.constant_i64(&format!("{name}.all"), &[n], &all);
    let (start, end) = if r > 1 {
        let rr = g.constant_i64(&format!("{name}.factor"), &[1], &[r as i64]);
        (
            g.node("Mul", &format!("{name}.start"), &[start, &rr], vec![]),
            g.node("Mul", &format!("{name}.end"), &[end, &rr], vec![]),
        )
    } else {
        (start.to_string(), end.to_string())
    };
    let before = g.node("Less", &format!("{name}.before"), &[&all, &start], vec![]);
    let from = g.node("Not", &format!("{name}.from"), &[&before], vec![]);
    let to = g.node("Less", &format!("{name}.to"), &[&all, &end], vec![]);
    let inside = g.node("And", &format!("{name}.inside"), &[&from, &to], vec![]);
    let at = g.node("NonZero", &format!("{name}.at"), &[&inside], vec![]);
    let flat = g.constant_i64(&format!("{name}.flat"), &[1], &[-1]);
    g.node("Reshape", name, &[&at, &flat], vec![])
}

/// The rows of a batch that the true entries of a mask hold, in the order `NonZero` lists
/// them (`indices`, int64 `[n]`): entry k (row-major) is row `first + k` (`first` 0 when
/// `None`; int64 `[1]` otherwise). An index list sized by the mask's `NonZero`, for a
/// Gather: runtimes do not all size a Slice of computed bounds (tract's fails to run).
///
/// # Shapes
/// - `mask_i64`: int64 `[m]`, 0 or 1; returns int64 `[n]`
pub(crate) fn rank_rows(
    g: &mut GraphBuilder,
    prefix: &str,
    mask_i64: &str,
    indices: &str,
    first: Option<&str>,
) -> String {
    let name = |n: &str| format!("{prefix}.{n}");
    // Ranks summed in f32 (exact to 2^24 entries): tract sums no integers.
    let mask = g.node(
        "Cast",
        &name("mask_f32"),
        &[mask_i64],
        vec![attr_int("to", DataType::Float as i64)],
    );
    let axis0 = g.constant_i64(&name("rank_axis"), &[], &[0]);
    let ranks = g.node("CumSum", &name("ranks_f32"), &[&mask, &axis0], vec![]);
    let ranks = g.node(
        "Cast",
        &name("ranks_all"),
        &[&ranks],
        vec![attr_int("to", DataType::Int64 as i64)],
    );
    let ranks = g.node(
        "Gather",
        &name("ranks"),
        &[&ranks, indices],
        vec![attr_int("axis", 0)],
    );
    // Ranks count from 1.
    let one = g.constant_i64(&name("rank_one"), &[1], &[1]);
    let offset = match first {
        Some(first) => g.node("Sub", &name("first_row"), &[first, &one], vec![]),
        None => g.node("Neg", &name("first_row"), &[&one], vec![]),
    };
    g.node("Add", &name("row_index"), &[&ranks, &offset], vec![])
}
