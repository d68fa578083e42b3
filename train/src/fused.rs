//! The fused dense layer as a candle custom op: `act(x W^T + addend)` forward in one pass,
//! and a backward that computes the ReLU mask, the addend's gradient and the input and
//! weight gradients with the parallel kernels of [`crate::kernels`]. Gradients are only
//! computed for arguments that take part in backpropagation (the encoded sample positions
//! never need one).

use candle_core::{CpuStorage, CustomOp3, Layout, Result, Shape, Storage, Tensor};

use crate::kernels::{Addend, linear_forward, matmul, matmul_tn, relu_backward};

/// Which rows of the output an addend row serves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AddTo {
    /// `[n]`: every row (a bias).
    Every,
    /// `[m / group, n]`: each group of `group` consecutive rows (a per-ray term).
    Groups(usize),
    /// `[m, n]`: row by row.
    Each,
}

struct FusedLinear {
    relu: bool,
    add: AddTo,
}

fn cpu_slice<'a>(s: &'a CpuStorage, l: &Layout, what: &str) -> Result<&'a [f32]> {
    let data = s.as_slice::<f32>()?;
    match l.contiguous_offsets() {
        Some((a, b)) => Ok(&data[a..b]),
        None => candle_core::bail!("fused linear: `{what}` must be contiguous"),
    }
}

/// Runs `f` on the contiguous f32 data of `t` (copied only if `t` is not contiguous).
fn with_data<R>(t: &Tensor, what: &str, f: impl FnOnce(&[f32]) -> Result<R>) -> Result<R> {
    let t = t.contiguous()?;
    let (storage, layout) = t.storage_and_layout();
    match &*storage {
        Storage::Cpu(cpu) => f(cpu_slice(cpu, layout, what)?),
        _ => candle_core::bail!("fused linear runs on the CPU only"),
    }
}

impl FusedLinear {
    fn mode(&self) -> Addend {
        match self.add {
            AddTo::Every => Addend::Row,
            AddTo::Groups(g) => Addend::Group(g),
            AddTo::Each => Addend::Full,
        }
    }
}

impl CustomOp3 for FusedLinear {
    fn name(&self) -> &'static str {
        "nldf-fused-linear"
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
        let (m, k) = l1.shape().dims2()?;
        let (n, k2) = l2.shape().dims2()?;
        if k != k2 {
            candle_core::bail!("fused linear: input [{m}, {k}] does not fit weight [{n}, {k2}]");
        }
        let want: Vec<usize> = match self.add {
            AddTo::Every => vec![n],
            AddTo::Groups(g) => vec![m / g.max(1), n],
            AddTo::Each => vec![m, n],
        };
        if l3.shape().dims() != want.as_slice()
            || matches!(self.add, AddTo::Groups(g) if g == 0 || m % g != 0)
        {
            candle_core::bail!(
                "fused linear: addend of shape {:?} does not fit {:?} for {m} rows",
                l3.shape().dims(),
                self.add
            );
        }
        let x = cpu_slice(s1, l1, "x")?;
        let w = cpu_slice(s2, l2, "weight")?;
        let a = cpu_slice(s3, l3, "addend")?;
        let mut y = vec![0.0f32; m * n];
        linear_forward(x, m, k, w, n, a, self.mode(), self.relu, &mut y);
        Ok((CpuStorage::F32(y), Shape::from((m, n))))
    }

    fn bwd(
        &self,
        x: &Tensor,
        w: &Tensor,
        addend: &Tensor,
        y: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        let (m, k) = x.dims2()?;
        let (n, _) = w.dims2()?;
        let dev = x.device();
        let (gm, da) = with_data(grad, "grad", |g| {
            with_data(y, "output", |yv| {
                Ok(relu_backward(g, yv, m, n, self.relu, self.mode()))
            })
        })?;
        let dx = if x.track_op() {
            let mut dx = vec![0.0f32; m * k];
            with_data(w, "weight", |wv| {
                matmul(&gm, m, n, wv, k, &mut dx);
                Ok(())
            })?;
            Some(Tensor::from_vec(dx, (m, k), dev)?)
        } else {
            None
        };
        let dw = if w.track_op() {
            let mut dw = vec![0.0f32; n * k];
            with_data(x, "x", |xv| {
                matmul_tn(&gm, m, n, xv, k, &mut dw);
                Ok(())
            })?;
            Some(Tensor::from_vec(dw, (n, k), dev)?)
        } else {
            None
        };
        let da = if addend.track_op() {
            Some(Tensor::from_vec(da, addend.shape(), dev)?)
        } else {
            None
        };
        Ok((dx, dw, da))
    }
}

/// `act(x W^T + addend)` with `act` a ReLU or nothing, fused; differentiable in all three.
///
/// # Shapes
/// - `x`: `[m, k]`; `weight`: `[n, k]`; returns `[m, n]`
/// - `addend`: `[n]` ([`AddTo::Every`]), `[m / g, n]` ([`AddTo::Groups`]) or `[m, n]`
///   ([`AddTo::Each`])
pub fn fused_linear(
    x: &Tensor,
    weight: &Tensor,
    addend: &Tensor,
    add: AddTo,
    relu: bool,
) -> Result<Tensor> {
    x.contiguous()?.apply_op3(
        &weight.contiguous()?,
        &addend.contiguous()?,
        FusedLinear { relu, add },
    )
}
