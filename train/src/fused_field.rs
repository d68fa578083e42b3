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

use std::sync::Mutex;

use candle_core::{CpuStorage, CustomOp3, Layout, Result, Shape, Storage, Tensor};

use crate::kernels::{
    Addend, give_buffer, linear_forward, matmul, matmul_tn, relu_backward, take_buffer,
};

/// A weight `[out, inp]` (and bias `[out]`) inside the flat parameter tensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Affine {
    pub weight: usize,
    pub bias: Option<usize>,
    pub out: usize,
    pub inp: usize,
}

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
    stash: Mutex<Option<Stash>>,
}

impl FieldOp {
    /// An op for `plan`; `keep` activations when a backward pass will follow.
    pub fn new(plan: FieldPlan, keep: bool) -> FieldOp {
        FieldOp {
            plan,
            keep,
            stash: Mutex::new(None),
        }
    }
}

/// Collects the flat parameter tensor of a fused op: the variables, flattened and
/// concatenated, so that candle routes each slice of the op's parameter gradient back to
/// its variable.
#[derive(Debug, Default)]
pub(crate) struct Packer {
    parts: Vec<Tensor>,
    len: usize,
}

impl Packer {
    fn push(&mut self, t: &Tensor) -> Result<usize> {
        let at = self.len;
        self.len += t.elem_count();
        self.parts.push(t.flatten_all()?);
        Ok(at)
    }

    /// Adds a layer's weight `[out, inp]` and optional bias `[out]`.
    pub(crate) fn affine(&mut self, weight: &Tensor, bias: Option<&Tensor>) -> Result<Affine> {
        let (out, inp) = weight.dims2()?;
        let w = self.push(weight)?;
        let bias = match bias {
            Some(b) => Some(self.push(b)?),
            None => None,
        };
        Ok(Affine {
            weight: w,
            bias,
            out,
            inp,
        })
    }

    /// Values packed so far.
    pub(crate) fn len(&self) -> usize {
        self.len
    }

    /// The flat parameter tensor `[len]`.
    pub(crate) fn tensor(&self) -> Result<Tensor> {
        Tensor::cat(&self.parts, 0)
    }
}

pub(crate) fn contiguous<'a>(s: &'a CpuStorage, l: &Layout, what: &str) -> Result<&'a [f32]> {
    let data = s.as_slice::<f32>()?;
    match l.contiguous_offsets() {
        Some((a, b)) => Ok(&data[a..b]),
        None => candle_core::bail!("fused field: `{what}` must be contiguous"),
    }
}

pub(crate) fn with_data<R>(
    t: &Tensor,
    what: &str,
    f: impl FnOnce(&[f32]) -> Result<R>,
) -> Result<R> {
    let t = t.contiguous()?;
    let (storage, layout) = t.storage_and_layout();
    match &*storage {
        Storage::Cpu(cpu) => f(contiguous(cpu, layout, what)?),
        _ => candle_core::bail!("the fused field runs on the CPU only"),
    }
}

/// Column block `[.., off..off + w]` of a `[rows, width]` matrix, contiguous.
fn block(m: &[f32], width: usize, off: usize, w: usize) -> Vec<f32> {
    m.chunks_exact(width)
        .flat_map(|row| row[off..off + w].iter().copied())
        .collect()
}

pub(crate) fn weight<'a>(p: &'a [f32], a: &Affine) -> &'a [f32] {
    &p[a.weight..a.weight + a.out * a.inp]
}

pub(crate) fn bias_or_zero(p: &[f32], a: &Affine) -> Vec<f32> {
    match a.bias {
        Some(b) => p[b..b + a.out].to_vec(),
        None => vec![0.0; a.out],
    }
}

impl FieldOp {
    /// The forward pass on raw slices; returns `[n, 4]` (raw density, raw rgb) and the
    /// activations.
    fn run(
        &self,
        points: &[f32],
        params: &[f32],
        rays: &[f32],
        n: usize,
    ) -> Result<(Vec<f32>, Stash)> {
        let plan = &self.plan;
        let group = Addend::Group(plan.n_samples);
        let pos_dim = plan
            .trunk
            .first()
            .and_then(|s| s.points)
            .map(|a| a.inp)
            .ok_or_else(|| {
                candle_core::Error::Msg("fused field: the first layer takes no points".into())
            })?;
        let mut stash = Stash::default();
        let mut prev: Option<Vec<f32>> = None;
        for step in &plan.trunk {
            let width =
                step.hidden.or(step.points).map(|a| a.out).ok_or_else(|| {
                    candle_core::Error::Msg("fused field: empty trunk layer".into())
                })?;
            let mut y = take_buffer(n * width);
            match (step.hidden, step.points, step.ray, prev.as_deref()) {
                (None, Some(p), Some(off), _) => {
                    let term = block(rays, plan.ray_width, off, width);
                    linear_forward(
                        points,
                        n,
                        pos_dim,
                        weight(params, &p),
                        width,
                        &term,
                        group,
                        true,
                        &mut y,
                    );
                }
                (Some(h), Some(p), Some(off), Some(x)) => {
                    let term = block(rays, plan.ray_width, off, width);
                    let mut z = take_buffer(n * width);
                    linear_forward(
                        points,
                        n,
                        pos_dim,
                        weight(params, &p),
                        width,
                        &term,
                        group,
                        false,
                        &mut z,
                    );
                    linear_forward(
                        x,
                        n,
                        h.inp,
                        weight(params, &h),
                        width,
                        &z,
                        Addend::Full,
                        true,
                        &mut y,
                    );
                }
                (Some(h), None, _, Some(x)) => {
                    let b = bias_or_zero(params, &h);
                    linear_forward(
                        x,
                        n,
                        h.inp,
                        weight(params, &h),
                        width,
                        &b,
                        Addend::Row,
                        true,
                        &mut y,
                    );
                }
                _ => candle_core::bail!("fused field: a trunk layer lacks its input"),
            }
            if let Some(p) = prev.take() {
                if self.keep {
                    stash.trunk.push(p);
                } else {
                    give_buffer(p);
                }
            }
            prev = Some(y);
        }
        let h = prev.ok_or_else(|| candle_core::Error::Msg("fused field: empty trunk".into()))?;
        let (d, f, c, r) = (&plan.density, &plan.feature, &plan.color, &plan.rgb);
        let mut density = vec![0.0f32; n];
        linear_forward(
            &h,
            n,
            d.inp,
            weight(params, d),
            1,
            &bias_or_zero(params, d),
            Addend::Row,
            false,
            &mut density,
        );
        let mut feature = take_buffer(n * f.out);
        linear_forward(
            &h,
            n,
            f.inp,
            weight(params, f),
            f.out,
            &bias_or_zero(params, f),
            Addend::Row,
            false,
            &mut feature,
        );
        let term = block(rays, plan.ray_width, plan.color_ray, c.out);
        let mut color = take_buffer(n * c.out);
        linear_forward(
            &feature,
            n,
            c.inp,
            weight(params, c),
            c.out,
            &term,
            group,
            true,
            &mut color,
        );
        let mut rgb = vec![0.0f32; n * 3];
        linear_forward(
            &color,
            n,
            r.inp,
            weight(params, r),
            3,
            &bias_or_zero(params, r),
            Addend::Row,
            false,
            &mut rgb,
        );
        let mut out = vec![0.0f32; n * 4];
        for (i, o) in out.chunks_exact_mut(4).enumerate() {
            o[0] = density[i];
            o[1..].copy_from_slice(&rgb[3 * i..3 * i + 3]);
        }
        if self.keep {
            stash.trunk.push(h);
            stash.feature = feature;
            stash.color = color;
        } else {
            give_buffer(h);
            give_buffer(feature);
            give_buffer(color);
        }
        Ok((out, stash))
    }
}

impl CustomOp3 for FieldOp {
    fn name(&self) -> &'static str {
        "nldf-fused-field"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
        s3: &CpuStorage,
        l3: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let (n, _) = l1.shape().dims2()?;
        let plan = &self.plan;
        if l2.shape().elem_count() != plan.n_params {
            candle_core::bail!(
                "fused field: {} parameters given, the plan needs {}",
                l2.shape().elem_count(),
                plan.n_params
            );
        }
        let (n_rays, q) = l3.shape().dims2()?;
        if q != plan.ray_width || n_rays * plan.n_samples != n {
            candle_core::bail!(
                "fused field: per-ray terms [{n_rays}, {q}] do not fit {n} samples of {} per ray and width {}",
                plan.n_samples,
                plan.ray_width
            );
        }
        let points = contiguous(s1, l1, "points")?;
        let params = contiguous(s2, l2, "params")?;
        let rays = contiguous(s3, l3, "ray terms")?;
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
        let plan = &self.plan;
        let n = points.dim(0)?;
        let n_rays = rays.dim(0)?;
        let group = Addend::Group(plan.n_samples);
        let dev = points.device();
        let mut dp = vec![0.0f32; plan.n_params];
        let mut dr = vec![0.0f32; n_rays * plan.ray_width];
        let add_block = |dr: &mut [f32], off: usize, w: usize, g: &[f32]| {
            for (row, src) in dr.chunks_exact_mut(plan.ray_width).zip(g.chunks_exact(w)) {
                for (d, s) in row[off..off + w].iter_mut().zip(src) {
                    *d += s;
                }
            }
        };
        with_data(grad, "grad", |g| {
            with_data(params, "params", |p| {
                with_data(points, "points", |pts| {
                    let (d, f, c, r) = (&plan.density, &plan.feature, &plan.color, &plan.rgb);
                    let mut g_density: Vec<f32> = g.chunks_exact(4).map(|o| o[0]).collect();
                    let mut g_rgb: Vec<f32> = g
                        .chunks_exact(4)
                        .flat_map(|o| o[1..].iter().copied())
                        .collect();
                    let h = stash
                        .trunk
                        .last()
                        .ok_or_else(|| candle_core::Error::Msg("empty stash".into()))?;
                    // rgb = color W_r^T + b_r
                    let db = relu_backward(&mut g_rgb, &[], n, 3, false, Addend::Row);
                    accumulate_affine(&mut dp, r, &g_rgb, &stash.color, n, Some(&db));
                    let mut g_color = take_buffer(n * c.out);
                    matmul(&g_rgb, n, 3, weight(p, r), c.out, &mut g_color);
                    // color = relu(feature W_c^T + ray term)
                    let d_term = relu_backward(&mut g_color, &stash.color, n, c.out, true, group);
                    add_block(&mut dr, plan.color_ray, c.out, &d_term);
                    accumulate_affine(&mut dp, c, &g_color, &stash.feature, n, None);
                    let mut g_feature = take_buffer(n * f.out);
                    matmul(&g_color, n, c.out, weight(p, c), f.out, &mut g_feature);
                    give_buffer(g_color);
                    // feature = h W_f^T + b_f, density = h W_d^T + b_d
                    let db_f = relu_backward(&mut g_feature, &[], n, f.out, false, Addend::Row);
                    accumulate_affine(&mut dp, f, &g_feature, h, n, Some(&db_f));
                    let db_d = relu_backward(&mut g_density, &[], n, 1, false, Addend::Row);
                    accumulate_affine(&mut dp, d, &g_density, h, n, Some(&db_d));
                    let width = f.inp;
                    let mut g_h = take_buffer(n * width);
                    matmul(&g_feature, n, f.out, weight(p, f), width, &mut g_h);
                    give_buffer(g_feature);
                    let wd = weight(p, d);
                    for (row, &gd) in g_h.chunks_exact_mut(width).zip(&g_density) {
                        for (x, w) in row.iter_mut().zip(wd) {
                            *x += gd * w;
                        }
                    }
                    // The trunk, last layer first. A fed layer's addend (its per-ray term,
                    // which carries its bias) gets the group sums; a plain layer's bias the
                    // row sums.
                    for (i, step) in plan.trunk.iter().enumerate().rev() {
                        let y = &stash.trunk[i];
                        let w_out = step.hidden.or(step.points).map(|a| a.out).unwrap_or(width);
                        let mode = match (step.points, step.hidden) {
                            (Some(_), _) => group,
                            (None, Some(hid)) if hid.bias.is_some() => Addend::Row,
                            _ => Addend::None,
                        };
                        let d_add = relu_backward(&mut g_h, y, n, w_out, true, mode);
                        if let (Some(pa), Some(off)) = (step.points, step.ray) {
                            accumulate_affine(&mut dp, &pa, &g_h, pts, n, None);
                            add_block(&mut dr, off, w_out, &d_add);
                        }
                        if let Some(hid) = step.hidden {
                            let x = &stash.trunk[i - 1];
                            let db = (mode == Addend::Row).then_some(&d_add);
                            accumulate_affine(&mut dp, &hid, &g_h, x, n, db);
                            let mut g_x = take_buffer(n * hid.inp);
                            matmul(&g_h, n, w_out, weight(p, &hid), hid.inp, &mut g_x);
                            give_buffer(std::mem::replace(&mut g_h, g_x));
                        }
                    }
                    give_buffer(g_h);
                    Ok(())
                })
            })
        })?;
        stash.trunk.into_iter().for_each(give_buffer);
        give_buffer(stash.feature);
        give_buffer(stash.color);
        let d_params = Tensor::from_vec(dp, params.shape(), dev)?;
        let d_rays = Tensor::from_vec(dr, rays.shape(), dev)?;
        Ok((None, Some(d_params), Some(d_rays)))
    }
}

/// Adds `g^T x` to the weight's gradient and `db` to the bias's.
pub(crate) fn accumulate_affine(
    dp: &mut [f32],
    a: &Affine,
    g: &[f32],
    x: &[f32],
    n: usize,
    db: Option<&Vec<f32>>,
) {
    let mut dw = vec![0.0f32; a.out * a.inp];
    matmul_tn(g, n, a.out, x, a.inp, &mut dw);
    for (d, v) in dp[a.weight..a.weight + a.out * a.inp].iter_mut().zip(&dw) {
        *d += v;
    }
    if let (Some(b), Some(db)) = (a.bias, db) {
        for (d, v) in dp[b..b + a.out].iter_mut().zip(db) {
            *d += v;
        }
    }
}
