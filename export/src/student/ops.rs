//! The student's Linear and Conv1d layers, read from the checkpoint by their paths.

use crate::checkpoint::StudentCheckpoint;
use crate::error::{Error, Result};
use crate::graph::{GraphBuilder, attr_float, attr_int, attr_ints};
use nldf_core::student_network::Conv1dLayer;

/// AD-NeRF's LeakyReLU slope.
const SLOPE: f32 = 0.02;

/// `x W^T + b` with the checkpoint's Linear `name` for a product every ray passes through:
/// in int8 under [`crate::graph::WeightType::Int8`] ([`GraphBuilder::matmul_int8`]) unless kept in f32
/// ([`GraphBuilder::int8_product`]), else as [`linear`].
pub(super) fn ray_linear(
    g: &mut GraphBuilder,
    ckpt: &StudentCheckpoint,
    name: &str,
    x: &str,
    in_dim: usize,
    out_dim: usize,
) -> Result<String> {
    g.tap(name, x, in_dim);
    if !g.int8_product(name) {
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
pub(super) fn linear(
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

/// The checkpoint's Conv1d of the described layer `c` (`weight` `[c_out, c_in, kernel]`)
/// followed by LeakyReLU 0.02.
pub(super) fn conv_leaky(
    g: &mut GraphBuilder,
    ckpt: &StudentCheckpoint,
    c: &Conv1dLayer,
    x: &str,
) -> Result<String> {
    let name = c.path();
    let shape = [c.c_out, c.c_in, c.kernel];
    let w = ckpt.weight(&format!("{name}.weight"), &shape)?;
    let b = ckpt.weight(&format!("{name}.bias"), &[c.c_out])?;
    let w = g.weight(&format!("{name}.weight"), &shape, w);
    let b = g.weight(&format!("{name}.bias"), &[c.c_out], b);
    let pad = c.padding() as i64;
    let y = g.node(
        "Conv",
        &name,
        &[x, &w, &b],
        vec![
            attr_ints("kernel_shape", &[c.kernel as i64]),
            attr_ints("strides", &[c.stride as i64]),
            attr_ints("pads", &[pad, pad]),
            attr_ints("dilations", &[1]),
            attr_int("group", 1),
        ],
    );
    Ok(leaky(g, &format!("{name}.act"), &y))
}

/// LeakyReLU with AD-NeRF's slope.
pub(super) fn leaky(g: &mut GraphBuilder, name: &str, x: &str) -> String {
    g.node("LeakyRelu", name, &[x], vec![attr_float("alpha", SLOPE)])
}
