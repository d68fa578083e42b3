//! ONNX layers the graphs share, each written once: a padded convolution, bilinear
//! upsampling as a transposed convolution with fixed weights, and depth-to-space.

use nldf_core::upsampler_config::bilinear_kernel;

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
