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

mod backward;
mod forward;

use std::sync::Mutex;

use candle_core::{CpuStorage, CustomOp3, Layout, Result, Shape, Tensor};

use crate::kernels::{Packed, give_buffer};
use crate::ops::op_base::{Affine, contiguous, weight, with_data};

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
