//! Beam encoding (paper section 3.2): each ray's K points, anchored where the student was
//! trained with an anchor, clamped and positionally encoded as `nldf_core::encoding` does.

use nldf_core::beam::{BeamAnchor, MIN_DIRECTION_LENGTH};
use nldf_core::encoding::MAX_COORD;
use nldf_model::onnx::DataType;

use crate::checkpoint::StudentCheckpoint;
use crate::graph::{GraphBuilder, attr_int};

/// Beam encoding: points `x_k = o + t_k d` at the K evenly spaced `t_k` of
/// `BeamSpec::t_value`, flattened to `[x_0, y_0, z_0, x_1, ...]`, clamped to
/// `±MAX_COORD`, then `[x | sin(2^0 x) | cos(2^0 x) | ... | cos(2^(L-1) x)]`, the octaves
/// above the first by the double-angle identities in f64, as `nldf_core::encoding` computes
/// them.
///
/// # Shapes
/// - `origins`, `directions`: `[n_rays, 3]`
/// - returns `beam.encoded` `[n_rays, 3 K (1 + 2 L)]`
pub(super) fn encode_beams(
    g: &mut GraphBuilder,
    ckpt: &StudentCheckpoint,
    origins: &str,
    directions: &str,
) -> String {
    let l = ckpt.shape.beam.n_freqs;
    let (x, lo, hi) = beam_points(g, ckpt, origins, directions);
    if l == 0 {
        return g.node("Identity", "beam.encoded", &[&x], vec![]);
    }
    encode_points(g, &x, l, (&lo, &hi))
}

/// The beam points `o + t_k d`, flattened and clamped to `±MAX_COORD`: `beam.points`
/// `[n_rays, 3 K]`, with the clamp's bounds.
fn beam_points(
    g: &mut GraphBuilder,
    ckpt: &StudentCheckpoint,
    origins: &str,
    directions: &str,
) -> (String, String, String) {
    let beam = ckpt.shape.beam;
    let (near, far) = (ckpt.spec.near, ckpt.spec.far);
    let k = beam.n_points;
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
    (x, lo, hi)
}

/// The positional encoding of the clamped points `x` with `l` octaves, clamped once more
/// by `lo` and `hi`: `beam.encoded` `[n_rays, 3 K (1 + 2 L)]`.
fn encode_points(g: &mut GraphBuilder, x: &str, l: usize, (lo, hi): (&str, &str)) -> String {
    // As `nldf_core::encoding` computes it, op for op: sin and cos at the lowest octave,
    // then the double-angle identities of `nldf_core::encoding::double_angle`, all in
    // double precision, rounded to f32 once. 2 transcendental ops per value instead of 2 L
    // (runtimes without vectorised Sin/Cos spend most of a frame there), and the f64 climb
    // keeps each value within an f32 rounding of the exact sine.
    let double = DataType::Double as i64;
    let xd = g.node(
        "Cast",
        "beam.points_f64",
        &[x],
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
    g.node("Clip", "beam.encoded", &[&encoded, lo, hi], vec![])
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
