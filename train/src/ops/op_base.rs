//! What nldf's two fused candle ops share ([`crate::ops::field_op`], the teacher's per-sample
//! network, and [`crate::ops::student_op`], the student's residual MLP): the flat parameter
//! tensor they take (a `cat` of candle's variables, so that each slice of its gradient flows
//! back to its variable), where each affine layer lies in it, access to contiguous CPU
//! data, and the accumulation of an affine layer's gradients.

use candle_core::{CpuStorage, Layout, Result, Storage, Tensor};

use crate::kernels::matmul_tn;

/// A weight `[out, inp]` (and bias `[out]`) inside the flat parameter tensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Affine {
    /// Offset of the weight `[out, inp]` in the flat parameters.
    pub weight: usize,
    /// Offset of the bias `[out]`, when the layer has one.
    pub bias: Option<usize>,
    /// Output width.
    pub out: usize,
    /// Input width.
    pub inp: usize,
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
        None => candle_core::bail!("fused op: `{what}` must be contiguous"),
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
        _ => candle_core::bail!("the fused ops run on the CPU only"),
    }
}

/// Where an affine layer's weight lies in the flat parameters.
pub(crate) fn weight_range(a: &Affine) -> std::ops::Range<usize> {
    a.weight..a.weight + a.out * a.inp
}

pub(crate) fn weight<'a>(p: &'a [f32], a: &Affine) -> &'a [f32] {
    &p[weight_range(a)]
}

/// The bias of `a` as a slice of the parameters (none: no bias).
pub(crate) fn bias_of<'a>(p: &'a [f32], a: &Affine) -> Option<&'a [f32]> {
    a.bias.map(|b| &p[b..b + a.out])
}

pub(crate) fn bias_or_zero(p: &[f32], a: &Affine) -> Vec<f32> {
    bias_of(p, a).map_or_else(|| vec![0.0; a.out], <[f32]>::to_vec)
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
    for (d, v) in dp[weight_range(a)].iter_mut().zip(&dw) {
        *d += v;
    }
    if let (Some(b), Some(db)) = (a.bias, db) {
        for (d, v) in dp[b..b + a.out].iter_mut().zip(db) {
            *d += v;
        }
    }
}
