//! The student's residual MLP on `[beam | code]` and the segment sum (paper Eq. 7).

use nldf_model::contract::{OUTPUT_OPACITY, OUTPUT_RGB, OUTPUT_SEGMENTS};

use super::ops::{linear, ray_linear};
use crate::checkpoint::StudentCheckpoint;
use crate::error::{Error, Result};
use crate::graph::{GraphBuilder, attr_int};
use nldf_core::student_config::StudentConfig;
use nldf_core::student_network::{LinearLayer, MlpLayout};

/// The residual MLP on `[beam | code]` and the segment sum. The input layer's weight is
/// split by columns into its beam part and its audio part, so that the audio term is
/// computed once per frame and broadcast over the rays instead of concatenating the code
/// to every beam. Produces the graph outputs.
///
/// # Shapes
/// - `beams`: `[n_rays, 3 K (1 + 2 L)]`; `code`: `[1, dim]`; `background` `[n_rays, 3]`
/// - outputs `segments` `[n_rays, M, 3]`, `rgb` `[n_rays, 3]` (over `background` when
///   given) and `opacity` `[n_rays, 1]`
pub(super) fn residual_mlp(
    g: &mut GraphBuilder,
    ckpt: &StudentCheckpoint,
    beams: &str,
    code: &str,
    background: Option<&str>,
) -> Result<()> {
    let s = &ckpt.shape;
    let layout = MlpLayout::of(s);
    let x = input_layer(g, ckpt, &layout.input, beams, code)?;
    let mut h = g.node(
        "Relu",
        &format!("{}.act", layout.input.path()),
        &[&x],
        vec![],
    );
    let dense = |g: &mut GraphBuilder, l: &LinearLayer, x: &str| {
        ray_linear(g, ckpt, &l.path(), x, l.fan_in, l.fan_out)
    };
    for b in &layout.body {
        let p = b.path();
        let y = dense(g, &b.fc1, &h)?;
        let y = g.node("Relu", &format!("{}.act", b.fc1.path()), &[&y], vec![]);
        let y = dense(g, &b.fc2, &y)?;
        let sum = g.node("Add", &format!("{p}.skip"), &[&h, &y], vec![]);
        h = g.node("Relu", &format!("{p}.act"), &[&sum], vec![]);
    }
    // The output layer stays in f32 under int8: its 3 M outputs are the colours
    // themselves, and it costs a twentieth of a hidden layer.
    let o = &layout.output;
    let out = linear(g, ckpt, &o.path(), &h, o.fan_in, o.fan_out)?;
    let colours = segment_colours(g, s, out);
    segment_sum(g, s, &colours, background);
    Ok(())
}

/// The input layer, `[beam | code] W^T + b`, its weight split by columns: the audio term
/// once per frame, broadcast over the beams' product. `mlp.input` `[n_rays, width]`.
fn input_layer(
    g: &mut GraphBuilder,
    ckpt: &StudentCheckpoint,
    layer: &LinearLayer,
    beams: &str,
    code: &str,
) -> Result<String> {
    let s = &ckpt.shape;
    let (w, in_dim, name) = (layer.fan_out, layer.fan_in, layer.path());
    let beam_dim = s.beam.encoded_len();
    let weight = ckpt.weight(&format!("{name}.weight"), &[w, in_dim])?;
    let bias = ckpt.weight(&format!("{name}.bias"), &[w])?;
    let (mut w_beam, mut w_code) = (
        Vec::with_capacity(w * beam_dim),
        Vec::with_capacity(w * s.audio.dim),
    );
    for row in weight.chunks_exact(in_dim) {
        w_beam.extend_from_slice(&row[..beam_dim]);
        w_code.extend_from_slice(&row[beam_dim..]);
    }
    let w_code = g.weight(&format!("{name}.weight.audio"), &[w, s.audio.dim], &w_code);
    let bias = g.weight(&format!("{name}.bias"), &[w], bias);
    let audio_term = g.node(
        "Gemm",
        &format!("{name}.audio"),
        &[code, &w_code, &bias],
        vec![attr_int("transB", 1)],
    );
    g.tap(&format!("{name}.beam"), beams, beam_dim);
    let x = if g.int8_product(&format!("{name}.beam")) {
        let product = g
            .matmul_int8(&format!("{name}.beam"), beams, &w_beam, w, beam_dim)
            .map_err(Error::Calibration)?;
        g.node("Add", &name, &[&product, &audio_term], vec![])
    } else {
        let w_beam = g.weight(&format!("{name}.weight.beam"), &[w, beam_dim], &w_beam);
        g.node(
            "Gemm",
            &name,
            &[beams, &w_beam, &audio_term],
            vec![attr_int("transB", 1)],
        )
    };
    Ok(x)
}

/// The output layer's segment colours, `[n_rays, 3 M]`, premultiplied by the opacity
/// ([`OUTPUT_OPACITY`]), the sigmoid of the output's last column.
fn segment_colours(g: &mut GraphBuilder, s: &StudentConfig, out: String) -> String {
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
}

/// The segment sum (Eq. 7): [`OUTPUT_SEGMENTS`] `[n_rays, M, 3]` and [`OUTPUT_RGB`]
/// `[n_rays, 3]`, composited over `background` when given (the upsampler's graph reads the
/// head's own colour, without one).
fn segment_sum(g: &mut GraphBuilder, s: &StudentConfig, colours: &str, background: Option<&str>) {
    let shape = g.constant_i64("mlp.segment_shape", &[3], &[0, s.segments as i64, 3]);
    let segments = g.node("Reshape", OUTPUT_SEGMENTS, &[colours, &shape], vec![]);
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
}
