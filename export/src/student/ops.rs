//! The student's Linear and Conv1d layers, read from the checkpoint by their paths.

use crate::checkpoint::StudentCheckpoint;
use crate::error::{Error, Result};
use crate::graph::{GraphBuilder, WeightType, attr_float, attr_int, attr_ints};

/// AD-NeRF's LeakyReLU slope.
const SLOPE: f32 = 0.02;

/// `x W^T + b` with the checkpoint's Linear `name` for a product every ray passes through:
/// in int8 under [`WeightType::Int8`] ([`GraphBuilder::matmul_int8`]), else as [`linear`].
pub(super) fn ray_linear(
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

/// The checkpoint's Conv1d `name` (`weight` `[out, in, 3]`, padding 1) followed by
/// LeakyReLU 0.02.
pub(super) fn conv_leaky(
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

/// LeakyReLU with AD-NeRF's slope.
pub(super) fn leaky(g: &mut GraphBuilder, name: &str, x: &str) -> String {
    g.node("LeakyRelu", name, &[x], vec![attr_float("alpha", SLOPE)])
}
