//! The fused field's backward pass: every gradient in one pass over blocks of whole rays,
//! the weight gradients summed per span in a fixed order.

use candle_core::Result;
use rayon::prelude::*;

use super::{FieldOp, PackedPlan, Stash, trunk_width};
use crate::kernels::{Epilogue, block_product, block_weight_grad};
use crate::ops::op_base::{Affine, weight_range};

/// Partial weight gradients of the backward, summed in order: a fixed number, so that the
/// result does not depend on the thread count.
const SPANS: usize = 16;

/// `acc[j] += sum_i g[i * ld + j]` over `rows` rows of `n` values (a bias gradient).
fn add_col_sums(g: &[f32], ld: usize, rows: usize, n: usize, acc: &mut [f32]) {
    for row in g.chunks(ld).take(rows) {
        for (a, v) in acc[..n].iter_mut().zip(&row[..n]) {
            *a += v;
        }
    }
}

/// Per ray, the sum of its `group` rows of `g` (`[rows, n]`, contiguous) added to its row
/// of `dr` (stride `ld`) at column `off`: the gradient of a per-ray term.
fn add_group_sums(g: &[f32], n: usize, group: usize, dr: &mut [f32], ld: usize, off: usize) {
    for (rows, d) in g.chunks(group * n).zip(dr.chunks_mut(ld)) {
        let d = &mut d[off..off + n];
        for row in rows.chunks_exact(n) {
            for (a, v) in d.iter_mut().zip(row) {
                *a += v;
            }
        }
    }
}

/// Adds a bias gradient (column sums of `g`) to the bias of `a`, if it has one.
fn add_bias_grad(dp: &mut [f32], a: &Affine, g: &[f32], ld: usize, rows: usize) {
    if let Some(b) = a.bias {
        add_col_sums(g, ld, rows, a.out, &mut dp[b..b + a.out]);
    }
}

/// The epilogue that zeroes a product where `gate <= 0` (the ReLU mask of the layer
/// whose output `gate` is).
fn gated(gate: &[f32]) -> Epilogue<'_> {
    Epilogue {
        gate: Some(gate),
        ..Epilogue::default()
    }
}

/// What [`FieldOp::backward`] gives: the parameters', the per-ray terms' and (when the op
/// gives one) the points' gradients.
type BackwardGrads = (Vec<f32>, Vec<f32>, Option<Vec<f32>>);

/// The backward's scratch for one span of blocks.
#[derive(Default)]
struct BackScratch {
    g_color: Vec<f32>,
    g_feature: Vec<f32>,
    g_h: Vec<f32>,
    g_x: Vec<f32>,
    packed: Vec<f32>,
}

/// `v` resized to `len` values (contents unspecified: the products overwrite them).
fn sized(v: &mut Vec<f32>, len: usize) -> &mut [f32] {
    if v.len() < len {
        v.resize(len, 0.0);
    }
    &mut v[..len]
}

impl FieldOp {
    /// The backward of one block of `rows` rows (whole rays) starting at row `r0`: adds
    /// the weight and bias gradients to `dp` and the per-ray term gradients to `dr` (the
    /// block's rays, `[rows / n_samples, ray_width]`). `g` is the block's output gradient
    /// `[rows, 4]` and `pts` its points; `dx`, when given, receives the points' gradient
    /// `[rows, pos_dim]` (zeroed by the caller).
    ///
    /// Every input gradient is stored already multiplied by the ReLU mask of the layer
    /// below (the gate of [`block_product`]), so it is never read back to be masked.
    #[allow(clippy::too_many_arguments)]
    fn backward_block(
        &self,
        w: &PackedPlan,
        stash: &Stash,
        r0: usize,
        rows: usize,
        g: &[f32],
        pts: &[f32],
        dp: &mut [f32],
        dr: &mut [f32],
        dx: Option<&mut [f32]>,
        s: &mut BackScratch,
    ) -> Result<()> {
        let plan = &self.plan;
        let (f, c) = (&plan.feature, &plan.color);
        // This block's rows of a kept activation `[n, width]`.
        let of = |width: usize| r0 * width..(r0 + rows) * width;
        let color = &stash.color[of(c.out)];
        let feature = &stash.feature[of(f.out)];
        let last = stash
            .trunk
            .len()
            .checked_sub(1)
            .ok_or_else(|| candle_core::Error::Msg("fused field: empty stash".into()))?;
        let width = f.inp;
        let h = &stash.trunk[last][of(width)];
        self.backward_color(w, color, feature, rows, g, dp, dr, s);
        self.backward_feature(w, h, rows, g, dp, s);
        self.backward_trunk(w, stash, r0, rows, pts, dp, dr, dx, s)
    }

    /// The backward of the rgb and colour layers over one block: their weight and bias
    /// gradients into `dp`, the colour layer's per-ray term gradient into `dr`, and the
    /// feature's gradient into `s.g_feature`.
    #[allow(clippy::too_many_arguments)]
    fn backward_color(
        &self,
        w: &PackedPlan,
        color: &[f32],
        feature: &[f32],
        rows: usize,
        g: &[f32],
        dp: &mut [f32],
        dr: &mut [f32],
        s: &mut BackScratch,
    ) {
        let plan = &self.plan;
        let (f, c, r) = (&plan.feature, &plan.color, &plan.rgb);
        let (ns, rw) = (plan.n_samples, plan.ray_width);
        // rgb = color W_r^T + b_r (columns 1..4 of g).
        block_weight_grad(
            &g[1..],
            4,
            3,
            color,
            c.out,
            c.out,
            rows,
            &mut dp[weight_range(r)],
            &mut s.packed,
        );
        add_bias_grad(dp, r, &g[1..], 4, rows);
        let g_color = sized(&mut s.g_color, rows * c.out);
        block_product(&g[1..], 4, rows, &w.rgb, g_color, c.out, gated(color));
        // color = relu(feature W_c^T + ray term).
        add_group_sums(g_color, c.out, ns, dr, rw, plan.color_ray);
        block_weight_grad(
            g_color,
            c.out,
            c.out,
            feature,
            f.out,
            f.out,
            rows,
            &mut dp[weight_range(c)],
            &mut s.packed,
        );
        let g_feature = sized(&mut s.g_feature, rows * f.out);
        block_product(
            g_color,
            c.out,
            rows,
            &w.color,
            g_feature,
            f.out,
            Epilogue::default(),
        );
    }

    /// The backward of the feature and density layers over one block, from the feature's
    /// gradient in `s.g_feature` and the density's in column 0 of `g`: their weight and
    /// bias gradients into `dp`, the last trunk layer's (`h`) gradient into `s.g_h`.
    fn backward_feature(
        &self,
        w: &PackedPlan,
        h: &[f32],
        rows: usize,
        g: &[f32],
        dp: &mut [f32],
        s: &mut BackScratch,
    ) {
        let (d, f) = (&self.plan.density, &self.plan.feature);
        let width = f.inp;
        let g_feature = &s.g_feature[..rows * f.out];
        // feature = h W_f^T + b_f, density = h W_d^T + b_d (column 0 of g).
        block_weight_grad(
            g_feature,
            f.out,
            f.out,
            h,
            width,
            width,
            rows,
            &mut dp[weight_range(f)],
            &mut s.packed,
        );
        add_bias_grad(dp, f, g_feature, f.out, rows);
        block_weight_grad(
            g,
            4,
            1,
            h,
            width,
            width,
            rows,
            &mut dp[weight_range(d)],
            &mut s.packed,
        );
        add_bias_grad(dp, d, g, 4, rows);
        let gh = sized(&mut s.g_h, rows * width);
        block_product(
            g_feature,
            f.out,
            rows,
            &w.feature,
            gh,
            width,
            Epilogue::default(),
        );
        block_product(
            g,
            4,
            rows,
            &w.density,
            gh,
            width,
            Epilogue {
                accumulate: true,
                gate: Some(h),
                ..Epilogue::default()
            },
        );
    }

    /// The trunk's backward over one block, last layer first, from the last layer's
    /// gradient in `s.g_h`: weight and bias gradients into `dp`, per-ray term gradients
    /// into `dr` and, when given, the points' gradient into `dx`.
    #[allow(clippy::too_many_arguments)]
    fn backward_trunk(
        &self,
        w: &PackedPlan,
        stash: &Stash,
        r0: usize,
        rows: usize,
        pts: &[f32],
        dp: &mut [f32],
        dr: &mut [f32],
        mut dx: Option<&mut [f32]>,
        s: &mut BackScratch,
    ) -> Result<()> {
        let plan = &self.plan;
        let (ns, rw) = (plan.n_samples, plan.ray_width);
        let of = |width: usize| r0 * width..(r0 + rows) * width;
        let mut g_h = std::mem::take(&mut s.g_h);
        let mut g_x = std::mem::take(&mut s.g_x);
        // The trunk, last layer first; `g_h` is the gradient of the layer's pre-activation.
        // A fed layer's per-ray term (which carries its bias) gets the group sums, a plain
        // layer's bias the column sums.
        for (i, (step, (wh, wp))) in plan.trunk.iter().zip(&w.trunk).enumerate().rev() {
            let w_out = trunk_width(step)?;
            let gh = &g_h[..rows * w_out];
            if let (Some(pa), Some(off)) = (step.points, step.ray) {
                add_group_sums(gh, w_out, ns, dr, rw, off);
                if let (Some(dx), Some(wp)) = (dx.as_deref_mut(), wp) {
                    let accumulate = Epilogue {
                        accumulate: true,
                        ..Epilogue::default()
                    };
                    block_product(gh, w_out, rows, wp, dx, pa.inp, accumulate);
                }
                block_weight_grad(
                    gh,
                    w_out,
                    w_out,
                    pts,
                    pa.inp,
                    pa.inp,
                    rows,
                    &mut dp[weight_range(&pa)],
                    &mut s.packed,
                );
            }
            if let (Some(hid), Some(wh)) = (step.hidden, wh) {
                let below = &stash.trunk[i - 1];
                let x = &below[of(hid.inp)];
                if step.points.is_none() {
                    add_bias_grad(dp, &hid, gh, w_out, rows);
                }
                block_weight_grad(
                    gh,
                    w_out,
                    w_out,
                    x,
                    hid.inp,
                    hid.inp,
                    rows,
                    &mut dp[weight_range(&hid)],
                    &mut s.packed,
                );
                let gx = sized(&mut g_x, rows * hid.inp);
                block_product(gh, w_out, rows, wh, gx, hid.inp, gated(x));
                std::mem::swap(&mut g_h, &mut g_x);
            }
        }
        s.g_h = g_h;
        s.g_x = g_x;
        Ok(())
    }

    /// The backward on raw slices, in parallel over [`SPANS`] spans of whole blocks: each
    /// span sums its blocks' weight gradients in order into its own partial, and the
    /// partials are added in span order. Returns the parameter and per-ray term gradients,
    /// and the points' gradient when the op gives one.
    pub(super) fn backward(
        &self,
        stash: &Stash,
        g: &[f32],
        params: &[f32],
        pts: &[f32],
        n_rays: usize,
    ) -> Result<BackwardGrads> {
        let plan = &self.plan;
        let pos_dim = self.pos_dim()?;
        let w = PackedPlan::new(plan, params, false);
        let rays_per_block = self.rays_per_block();
        let n_blocks = n_rays.div_ceil(rays_per_block);
        let span_rays = n_blocks.div_ceil(SPANS).max(1) * rays_per_block;
        let rw = plan.ray_width;
        let mut dr = vec![0.0f32; n_rays * rw];
        let ns = plan.n_samples;
        let mut dx = vec![
            0.0f32;
            if self.points_grad {
                n_rays * ns * pos_dim
            } else {
                0
            }
        ];
        let span_x = if self.points_grad {
            span_rays * ns * pos_dim
        } else {
            1
        };
        let mut dx_spans: Vec<Option<&mut [f32]>> = if self.points_grad {
            dx.chunks_mut(span_x).map(Some).collect()
        } else {
            Vec::new()
        };
        dx_spans.resize_with(n_rays.div_ceil(span_rays), || None);
        let partials = dr
            .par_chunks_mut(span_rays * rw)
            .zip(dx_spans.into_par_iter())
            .enumerate()
            .map(|(span, (dr, mut dx))| -> Result<Vec<f32>> {
                let mut dp = vec![0.0f32; plan.n_params];
                let mut scratch = BackScratch::default();
                let q_lo = span * span_rays;
                let q_hi = (q_lo + span_rays).min(n_rays);
                let mut q0 = q_lo;
                while q0 < q_hi {
                    let q1 = (q0 + rays_per_block).min(q_hi);
                    let (r0, r1) = (q0 * plan.n_samples, q1 * plan.n_samples);
                    self.backward_block(
                        &w,
                        stash,
                        r0,
                        r1 - r0,
                        &g[r0 * 4..r1 * 4],
                        &pts[r0 * pos_dim..r1 * pos_dim],
                        &mut dp,
                        &mut dr[(q0 - q_lo) * rw..(q1 - q_lo) * rw],
                        dx.as_deref_mut().map(|d| {
                            &mut d[(r0 - q_lo * ns) * pos_dim..(r1 - q_lo * ns) * pos_dim]
                        }),
                        &mut scratch,
                    )?;
                    q0 = q1;
                }
                Ok(dp)
            })
            .collect::<Result<Vec<_>>>()?;
        let mut dp = vec![0.0f32; plan.n_params];
        for part in &partials {
            for (d, v) in dp.iter_mut().zip(part) {
                *d += v;
            }
        }
        Ok((dp, dr, self.points_grad.then_some(dx)))
    }
}
