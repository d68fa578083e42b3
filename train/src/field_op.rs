//! The teacher field's per-sample network as one candle custom op.
//!
//! candle's autograd gives every intermediate gradient a zero-filled buffer and an add, which
//! for `[n_samples, width]` activations costs more memory traffic than the matrix products
//! themselves. This op runs the whole per-sample network (trunk, density, feature and colour
//! heads) forward with the fused kernels of [`crate::kernels`], keeps the activations it
//! needs, and computes every gradient in one backward pass. candle still owns the weights
//! and the optimizer: they enter as one flat tensor (a `cat` of the variables, so gradients
//! flow back to each), and the per-ray terms (audio code and view direction projections, with
//! the biases of the layers they enter) are computed by candle before the op.
//!
//! Both passes run layer by layer over blocks of whole rays (about 256 samples), so that a
//! block's activations and gradients stay in the core's L2 cache between layers: only the
//! kept activations go to memory, written once by the forward and read once by the backward.
//! The backward stores each input gradient already masked by the ReLU of the layer below.

use std::sync::Mutex;

use candle_core::{CpuStorage, CustomOp3, Layout, Result, Shape, Tensor};

use rayon::prelude::*;

use crate::kernels::{
    Addend, Epilogue, Packed, block_product, block_weight_grad, give_buffer, take_buffer,
};
use crate::op_base::{Affine, bias_of, contiguous, weight, weight_range, with_data};

/// One trunk layer: `relu(prev W_h^T [+ b_h] + points W_p^T + ray term)` with the parts
/// that layer has.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TrunkStep {
    pub hidden: Option<Affine>,
    pub points: Option<Affine>,
    /// Column offset of this layer's block in the per-ray terms (fed layers).
    pub ray: Option<usize>,
}

/// The static shape of the fused network.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FieldPlan {
    pub trunk: Vec<TrunkStep>,
    pub density: Affine,
    pub feature: Affine,
    /// The colour layer; its per-ray block (view direction and bias) is at `color_ray`.
    pub color: Affine,
    pub color_ray: usize,
    pub rgb: Affine,
    /// Samples per ray: rows `r * n_samples ..` share ray `r`'s terms.
    pub n_samples: usize,
    /// Width of the per-ray terms.
    pub ray_width: usize,
    /// Length of the flat parameter tensor.
    pub n_params: usize,
}

/// What the forward keeps for the backward.
#[derive(Debug, Default)]
struct Stash {
    /// Outputs of every trunk layer (after ReLU).
    trunk: Vec<Vec<f32>>,
    feature: Vec<f32>,
    color: Vec<f32>,
}

/// The op: plan, and the stash of one forward.
#[derive(Debug)]
pub struct FieldOp {
    pub plan: FieldPlan,
    /// Keep activations for a backward pass (training).
    pub keep: bool,
    /// Give the points their gradient in the backward (when they come from a learned
    /// encoding, such as the grid teacher's hash grid).
    pub points_grad: bool,
    stash: Mutex<Option<Stash>>,
}

impl FieldOp {
    /// An op for `plan`; `keep` activations when a backward pass will follow.
    pub fn new(plan: FieldPlan, keep: bool) -> FieldOp {
        FieldOp {
            plan,
            keep,
            points_grad: false,
            stash: Mutex::new(None),
        }
    }

    /// The same op, giving the points their gradient in the backward when `on`.
    pub fn with_points_grad(mut self, on: bool) -> FieldOp {
        self.points_grad = on;
        self
    }
}

/// Rows per block of the blocked passes, rounded to whole rays: a block's activations
/// (`[rows, width]` per layer) stay in the core's L2 cache from one layer to the next.
const BLOCK_ROWS: usize = 256;
/// Partial weight gradients of the backward, summed in order: a fixed number, so that the
/// result does not depend on the thread count.
const SPANS: usize = 16;

/// The op's weights packed for the kernels once per pass.
struct PackedPlan {
    /// Per trunk layer: the hidden and the points weight, `W^T` (forward) or `W` (backward).
    trunk: Vec<(Option<Packed>, Option<Packed>)>,
    density: Packed,
    feature: Packed,
    color: Packed,
    rgb: Packed,
}

impl PackedPlan {
    /// `W^T` of every layer (`transposed`) for the forward, or `W` for the input gradients.
    fn new(plan: &FieldPlan, params: &[f32], transposed: bool) -> PackedPlan {
        let pack = |a: &Affine| {
            if transposed {
                Packed::weight_t(weight(params, a), a.out, a.inp)
            } else {
                Packed::rows(weight(params, a), a.out, a.inp)
            }
        };
        PackedPlan {
            trunk: plan
                .trunk
                .iter()
                .map(|s| (s.hidden.as_ref().map(pack), s.points.as_ref().map(pack)))
                .collect(),
            density: pack(&plan.density),
            feature: pack(&plan.feature),
            color: pack(&plan.color),
            rgb: pack(&plan.rgb),
        }
    }
}

/// Output width of a trunk layer.
fn trunk_width(step: &TrunkStep) -> Result<usize> {
    step.hidden
        .or(step.points)
        .map(|a| a.out)
        .ok_or_else(|| candle_core::Error::Msg("fused field: empty trunk layer".into()))
}

/// One block's activations: each trunk layer's output, the feature and the colour layer.
struct BlockActs<'a> {
    trunk: Vec<&'a mut [f32]>,
    feature: &'a mut [f32],
    color: &'a mut [f32],
}

impl FieldOp {
    /// Rays per block of the blocked passes.
    fn rays_per_block(&self) -> usize {
        (BLOCK_ROWS / self.plan.n_samples.max(1)).max(1)
    }

    /// Width of the encoded points, which the first trunk layer takes.
    fn pos_dim(&self) -> Result<usize> {
        self.plan
            .trunk
            .first()
            .and_then(|s| s.points)
            .map(|a| a.inp)
            .ok_or_else(|| {
                candle_core::Error::Msg("fused field: the first layer takes no points".into())
            })
    }

    /// The forward pass over one block of whole rays: `rows` rows of `points`, the per-ray
    /// terms of those rays, outputs into `acts` and `out` (`[rows, 4]`: raw density, raw
    /// rgb).
    #[allow(clippy::too_many_arguments)]
    fn forward_block(
        &self,
        w: &PackedPlan,
        params: &[f32],
        points: &[f32],
        rays: &[f32],
        rows: usize,
        acts: &mut BlockActs<'_>,
        out: &mut [f32],
    ) -> Result<()> {
        let plan = &self.plan;
        let group = Addend::Group(plan.n_samples);
        let rw = plan.ray_width;
        // y = act(points W_p^T + the ray term at column `off`).
        let points_term = |wp: &Packed, off: usize, y: &mut [f32], width: usize, relu: bool| {
            let addend = Some((&rays[off..], rw, group));
            block_product(
                points,
                wp.k(),
                rows,
                wp,
                y,
                width,
                Epilogue {
                    addend,
                    relu,
                    ..Epilogue::default()
                },
            )
        };
        let mut in_width = 0;
        for (i, (step, (wh, wp))) in plan.trunk.iter().zip(&w.trunk).enumerate() {
            let width = trunk_width(step)?;
            let (done, rest) = acts.trunk.split_at_mut(i);
            let y = &mut *rest[0];
            let prev = done.last().map(|x| &**x);
            match (step.hidden, wh, wp, step.ray, prev) {
                // relu(points W_p^T + ray term), the ray term carrying the bias.
                (None, None, Some(wp), Some(off), _) => points_term(wp, off, y, width, true),
                // relu(x W_h^T + points W_p^T + ray term).
                (Some(_), Some(wh), Some(wp), Some(off), Some(x)) => {
                    points_term(wp, off, y, width, false);
                    block_product(
                        x,
                        in_width,
                        rows,
                        wh,
                        y,
                        width,
                        Epilogue {
                            accumulate: true,
                            relu: true,
                            ..Epilogue::default()
                        },
                    );
                }
                // relu(x W_h^T + b_h).
                (Some(h), Some(wh), None, _, Some(x)) => block_product(
                    x,
                    in_width,
                    rows,
                    wh,
                    y,
                    width,
                    Epilogue {
                        bias: bias_of(params, &h),
                        relu: true,
                        ..Epilogue::default()
                    },
                ),
                _ => candle_core::bail!("fused field: a trunk layer lacks its input"),
            }
            in_width = width;
        }
        let h = acts
            .trunk
            .last()
            .map(|h| &**h)
            .ok_or_else(|| candle_core::Error::Msg("fused field: empty trunk".into()))?;
        let (d, f, c, r) = (&plan.density, &plan.feature, &plan.color, &plan.rgb);
        let bias = |a: &Affine| Epilogue {
            bias: bias_of(params, a),
            ..Epilogue::default()
        };
        block_product(h, in_width, rows, &w.density, out, 4, bias(d));
        block_product(h, in_width, rows, &w.feature, acts.feature, f.out, bias(f));
        block_product(
            acts.feature,
            f.out,
            rows,
            &w.color,
            acts.color,
            c.out,
            Epilogue {
                addend: Some((&rays[plan.color_ray..], rw, group)),
                relu: true,
                ..Epilogue::default()
            },
        );
        block_product(acts.color, c.out, rows, &w.rgb, &mut out[1..], 4, bias(r));
        Ok(())
    }

    /// The forward pass on raw slices, in parallel over blocks of rays; returns `[n, 4]`
    /// (raw density, raw rgb) and, when kept, the activations.
    fn run(
        &self,
        points: &[f32],
        params: &[f32],
        rays: &[f32],
        n: usize,
    ) -> Result<(Vec<f32>, Stash)> {
        let plan = &self.plan;
        let pos_dim = self.pos_dim()?;
        let widths = plan
            .trunk
            .iter()
            .map(trunk_width)
            .collect::<Result<Vec<_>>>()?;
        let (f_out, c_out, rw) = (plan.feature.out, plan.color.out, plan.ray_width);
        let w = PackedPlan::new(plan, params, true);
        let rays_per_block = self.rays_per_block();
        let rb = rays_per_block * plan.n_samples;
        let mut out = vec![0.0f32; n * 4];
        let jobs = out
            .chunks_mut(rb * 4)
            .zip(points.chunks(rb * pos_dim))
            .zip(rays.chunks(rays_per_block * rw))
            .map(|((o, p), r)| (o, p, r));
        if self.keep {
            let mut stash = Stash {
                trunk: widths.iter().map(|&wd| take_buffer(n * wd)).collect(),
                feature: take_buffer(n * f_out),
                color: take_buffer(n * c_out),
            };
            let mut blocks: Vec<BlockActs<'_>> = stash
                .feature
                .chunks_mut(rb * f_out)
                .zip(stash.color.chunks_mut(rb * c_out))
                .map(|(feature, color)| BlockActs {
                    trunk: Vec::with_capacity(widths.len()),
                    feature,
                    color,
                })
                .collect();
            for (buf, &wd) in stash.trunk.iter_mut().zip(&widths) {
                for (b, chunk) in blocks.iter_mut().zip(buf.chunks_mut(rb * wd)) {
                    b.trunk.push(chunk);
                }
            }
            blocks
                .into_par_iter()
                .zip(jobs.collect::<Vec<_>>())
                .try_for_each(|(mut acts, (o, p, r))| {
                    self.forward_block(&w, params, p, r, o.len() / 4, &mut acts, o)
                })?;
            Ok((out, stash))
        } else {
            jobs.collect::<Vec<_>>().into_par_iter().try_for_each_init(
                || {
                    (
                        widths
                            .iter()
                            .map(|&wd| vec![0.0f32; rb * wd])
                            .collect::<Vec<_>>(),
                        vec![0.0f32; rb * f_out],
                        vec![0.0f32; rb * c_out],
                    )
                },
                |(trunk, feature, color), (o, p, r)| {
                    let rows = o.len() / 4;
                    let mut acts = BlockActs {
                        trunk: trunk.iter_mut().map(|t| &mut t[..]).collect(),
                        feature,
                        color,
                    };
                    self.forward_block(&w, params, p, r, rows, &mut acts, o)
                },
            )?;
            Ok((out, Stash::default()))
        }
    }
}

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
        mut dx: Option<&mut [f32]>,
        s: &mut BackScratch,
    ) -> Result<()> {
        let plan = &self.plan;
        let (d, f, c, r) = (&plan.density, &plan.feature, &plan.color, &plan.rgb);
        let (ns, rw) = (plan.n_samples, plan.ray_width);
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
        let mut g_h = std::mem::take(&mut s.g_h);
        let mut g_x = std::mem::take(&mut s.g_x);
        {
            let gh = sized(&mut g_h, rows * width);
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
    fn backward(
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

impl CustomOp3 for FieldOp {
    fn name(&self) -> &'static str {
        "nldf-fused-field"
    }

    fn cpu_fwd(
        &self,
        points_storage: &CpuStorage,
        points_layout: &Layout,
        params_storage: &CpuStorage,
        params_layout: &Layout,
        rays_storage: &CpuStorage,
        rays_layout: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let (n, _) = points_layout.shape().dims2()?;
        let plan = &self.plan;
        if params_layout.shape().elem_count() != plan.n_params {
            candle_core::bail!(
                "fused field: {} parameters given, the plan needs {}",
                params_layout.shape().elem_count(),
                plan.n_params
            );
        }
        let (n_rays, q) = rays_layout.shape().dims2()?;
        if q != plan.ray_width || n_rays * plan.n_samples != n {
            candle_core::bail!(
                "fused field: per-ray terms [{n_rays}, {q}] do not fit {n} samples of {} per ray and width {}",
                plan.n_samples,
                plan.ray_width
            );
        }
        let points = contiguous(points_storage, points_layout, "points")?;
        let params = contiguous(params_storage, params_layout, "params")?;
        let rays = contiguous(rays_storage, rays_layout, "ray terms")?;
        let (out, stash) = self.run(points, params, rays, n)?;
        if self.keep {
            let mut slot = self
                .stash
                .lock()
                .map_err(|_| candle_core::Error::Msg("fused field stash poisoned".into()))?;
            *slot = Some(stash);
        }
        Ok((CpuStorage::F32(out), Shape::from((n, 4))))
    }

    fn bwd(
        &self,
        points: &Tensor,
        params: &Tensor,
        rays: &Tensor,
        _out: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        let stash = self
            .stash
            .lock()
            .map_err(|_| candle_core::Error::Msg("fused field stash poisoned".into()))?
            .take()
            .ok_or_else(|| {
                candle_core::Error::Msg("fused field: backward without a kept forward".into())
            })?;
        let n_rays = rays.dim(0)?;
        let dev = points.device();
        let (dp, dr, dx) = with_data(grad, "grad", |g| {
            with_data(params, "params", |p| {
                with_data(points, "points", |pts| {
                    self.backward(&stash, g, p, pts, n_rays)
                })
            })
        })?;
        stash.trunk.into_iter().for_each(give_buffer);
        give_buffer(stash.feature);
        give_buffer(stash.color);
        let d_params = Tensor::from_vec(dp, params.shape(), dev)?;
        let d_rays = Tensor::from_vec(dr, rays.shape(), dev)?;
        let d_points = match dx {
            Some(dx) => Some(Tensor::from_vec(dx, points.shape(), dev)?),
            None => None,
        };
        Ok((d_points, Some(d_params), Some(d_rays)))
    }
}
