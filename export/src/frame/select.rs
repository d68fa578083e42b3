//! Rays in the frame graph: the pose's axes, the rays' directions, which rays meet a box
//! (the slab test), the indices of a mask's true entries and the rays those select.

use nldf_core::camera::Intrinsics;
use nldf_model::onnx::DataType;

use crate::graph::{GraphBuilder, attr_int, attr_ints};

/// The int64 indices `[n]` of the true entries of the bool mask `[m]`, row-major, and how
/// many there are, int64 `[1]`; the index nodes' names start with `prefixes.0`, the
/// count's with `prefixes.1`.
pub(super) fn mask_indices(
    g: &mut GraphBuilder,
    (at, count): (&str, &str),
    mask: &str,
) -> (String, String) {
    let hits = g.node("NonZero", &format!("{at}.hits_2d"), &[mask], vec![]);
    let flat = g.constant_i64(&format!("{at}.hits_shape"), &[1], &[-1]);
    // Counted from the mask, not from the indices' shape, which a runtime may hold
    // symbolically.
    let ones = g.node(
        "Cast",
        &format!("{count}.hit_count"),
        &[mask],
        vec![attr_int("to", DataType::Int64 as i64)],
    );
    let n_hit = g.node(
        "ReduceSum",
        &format!("{count}.n_rays"),
        &[&ones],
        vec![attr_int("keepdims", 1)],
    );
    let hits = g.node("Reshape", &format!("{at}.hits"), &[&hits, &flat], vec![]);
    (hits, n_hit)
}

/// Whether each ray `o + t d` meets the box `bounds` within `[near, far]`
/// (`Bounds::intersect`'s slab test, axis by axis), bool `[n]`; node names start with
/// `prefix`.
///
/// # Shapes
/// - `o`: `[1, 3]` or `[n, 3]`; `d`: `[n, 3]`
pub(super) fn slab_hits(
    g: &mut GraphBuilder,
    prefix: &str,
    bounds: &nldf_core::bounds::Bounds,
    (near, far): (f32, f32),
    (o, d): &(String, String),
) -> String {
    let name = |n: &str| format!("{prefix}.{n}");
    let lo = g.constant_f32(&name("lo"), &[1, 3], &bounds.lo.to_array());
    let hi = g.constant_f32(&name("hi"), &[1, 3], &bounds.hi.to_array());
    let to_lo = g.node("Sub", &name("to_lo"), &[&lo, o], vec![]);
    let to_hi = g.node("Sub", &name("to_hi"), &[&hi, o], vec![]);
    let u = g.node("Div", &name("u"), &[&to_lo, d], vec![]);
    let v = g.node("Div", &name("v"), &[&to_hi, d], vec![]);
    let enter = g.node("Min", &name("enter_raw"), &[&u, &v], vec![]);
    let exit = g.node("Max", &name("exit_raw"), &[&u, &v], vec![]);
    // An axis the ray runs parallel to: no limit from inside the slab, a miss from outside.
    let abs = g.node("Abs", &name("abs_d"), &[d], vec![]);
    let tiny = g.constant_f32(&name("parallel"), &[], &[1e-12]);
    let parallel = g.node("Less", &name("is_parallel"), &[&abs, &tiny], vec![]);
    let below = g.node("Less", &name("below"), &[o, &lo], vec![]);
    let above = g.node("Greater", &name("above"), &[o, &hi], vec![]);
    let outside = g.node("Or", &name("outside"), &[&below, &above], vec![]);
    let inf = g.constant_f32(&name("inf"), &[], &[f32::INFINITY]);
    let neg_inf = g.constant_f32(&name("neg_inf"), &[], &[f32::NEG_INFINITY]);
    let enter_par = g.node(
        "Where",
        &name("enter_parallel"),
        &[&outside, &inf, &neg_inf],
        vec![],
    );
    let exit_par = g.node(
        "Where",
        &name("exit_parallel"),
        &[&outside, &neg_inf, &inf],
        vec![],
    );
    let enter = g.node(
        "Where",
        &name("enter"),
        &[&parallel, &enter_par, &enter],
        vec![],
    );
    let exit = g.node(
        "Where",
        &name("exit"),
        &[&parallel, &exit_par, &exit],
        vec![],
    );
    let reduce = || vec![attr_ints("axes", &[1]), attr_int("keepdims", 0)];
    let t0 = g.node("ReduceMax", &name("t0_axes"), &[&enter], reduce());
    let t1 = g.node("ReduceMin", &name("t1_axes"), &[&exit], reduce());
    let near = g.constant_f32(&name("near"), &[], &[near]);
    let far = g.constant_f32(&name("far"), &[], &[far]);
    let t0 = g.node("Max", &name("t0"), &[&t0, &near], vec![]);
    let t1 = g.node("Min", &name("t1"), &[&t1, &far], vec![]);
    g.node("Greater", &name("hit"), &[&t1, &t0], vec![])
}

/// The rays `hits` selects: origins and directions `[n_hit, 3]`; node names start with
/// `prefix`.
pub(super) fn hit_rays(
    g: &mut GraphBuilder,
    prefix: &str,
    (origin, directions): &(String, String),
    hits: &str,
) -> (String, String) {
    let d = g.node(
        "Gather",
        &format!("{prefix}.directions"),
        &[directions, hits],
        vec![attr_int("axis", 0)],
    );
    let shape = g.node("Shape", &format!("{prefix}.ray_shape"), &[&d], vec![]);
    let o = g.node(
        "Expand",
        &format!("{prefix}.origins"),
        &[origin, &shape],
        vec![],
    );
    (o, d)
}

/// The pose's rotation columns as `[1, 1, 3]` each and its origin `[1, 3]`, node names
/// starting with `prefix`.
pub(super) fn pose_columns(
    g: &mut GraphBuilder,
    prefix: &str,
    pose: &str,
) -> ([String; 3], String) {
    let slice = |g: &mut GraphBuilder, name: &str, lo: [i64; 2], hi: [i64; 2]| {
        let lo = g.constant_i64(&format!("{name}.start"), &[2], &lo);
        let hi = g.constant_i64(&format!("{name}.end"), &[2], &hi);
        g.node("Slice", name, &[pose, &lo, &hi], vec![])
    };
    let column_shape = g.constant_i64(&format!("{prefix}.column_shape"), &[3], &[1, 1, 3]);
    let columns = [0i64, 1, 2].map(|c| {
        let col = slice(g, &format!("{prefix}.rotation{c}"), [0, c], [3, c + 1]);
        g.node(
            "Reshape",
            &format!("{prefix}.column{c}"),
            &[&col, &column_shape],
            vec![],
        )
    });
    let origin = slice(g, &format!("{prefix}.origin_column"), [0, 3], [3, 4]);
    let row = g.constant_i64(&format!("{prefix}.row_shape"), &[2], &[1, 3]);
    let origin = g.node(
        "Reshape",
        &format!("{prefix}.origin"),
        &[&origin, &row],
        vec![],
    );
    (columns, origin)
}

/// The directions `[n, 3]` of the rays through a grid of pixels: `(c0 x_i + c1 y_j) + c2
/// (-1)` from the pose's `columns` (`[1, 1, 3]` each, [`pose_columns`]) and the pixels'
/// camera-plane coordinates `xs` (`[1, w, 1]`) and `ys` (`[h, 1, 1]`), added in glam's
/// order, row by row; node names start with `prefix`.
pub(super) fn ray_directions(
    g: &mut GraphBuilder,
    prefix: &str,
    columns: &[String; 3],
    (xs, ys): (&str, &str),
) -> String {
    let name = |n: &str| format!("{prefix}.{n}");
    let along_x = g.node("Mul", &name("along_x"), &[&columns[0], xs], vec![]);
    let along_y = g.node("Mul", &name("along_y"), &[&columns[1], ys], vec![]);
    let across = g.node("Add", &name("across"), &[&along_x, &along_y], vec![]);
    let back = g.node("Neg", &name("back"), &[&columns[2]], vec![]);
    let d = g.node("Add", &name("directions_grid"), &[&across, &back], vec![]);
    let flat = g.constant_i64(&name("flat_shape"), &[2], &[-1, 3]);
    g.node("Reshape", &name("directions"), &[&d, &flat], vec![])
}

/// The camera-plane coordinates of the pixel columns (`x_i = (i - cx) / f`, `[w]`) and rows
/// (`y_j = -(j - cy) / f`, `[h]`), as `Intrinsics::camera_direction` makes them.
pub(super) fn pixel_coords(k: &Intrinsics) -> (Vec<f32>, Vec<f32>) {
    let xs = (0..k.width)
        .map(|i| k.camera_direction(i as f32, 0.0).x)
        .collect();
    let ys = (0..k.height)
        .map(|j| k.camera_direction(0.0, j as f32).y)
        .collect();
    (xs, ys)
}
