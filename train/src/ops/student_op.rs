//! The student's residual MLP as one candle custom op, forward and backward, on the kernels
//! of [`crate::kernels`].
//!
//! At 88 x 256 and 4096 rays, candle's own ops spend more time on zero-filled gradient
//! buffers, bias sums and element-wise passes than on the matrix products. This op keeps the activations the backward needs
//! (every block's hidden and output rows) and computes all gradients in one pass: the ReLU
//! mask and the bias sum in one sweep, the residual added in the product's epilogue. The
//! weights enter as one flat tensor (a `cat` of the variables), so candle's optimizer and
//! checkpoints still see the usual `mlp.*` variables.

use std::sync::Mutex;

use candle_core::{CpuStorage, CustomOp3, Layout, Result, Shape, Tensor};

use crate::kernels::{
    Addend, give_buffer, linear_forward, linear_forward_residual, matmul, matmul_add,
    relu_backward, take_buffer,
};
use crate::ops::op_base::{
    Affine, Packer, accumulate_affine, bias_or_zero, contiguous, weight, with_data,
};

/// One residual block's two layers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BlockPlan {
    pub fc1: Affine,
    pub fc2: Affine,
}

/// The static shape of the fused student network.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StudentPlan {
    /// `Linear(beam_dim + code_dim -> width)` + ReLU.
    pub input: Affine,
    pub blocks: Vec<BlockPlan>,
    /// `Linear(width -> 3 M)`, no activation.
    pub output: Affine,
    pub beam_dim: usize,
    pub code_dim: usize,
    pub n_params: usize,
}

impl StudentPlan {
    /// Packs the layers (weights and biases, in order) into a plan and its flat parameter
    /// tensor.
    pub fn pack(
        input: (&Tensor, &Tensor),
        blocks: &[[(&Tensor, &Tensor); 2]],
        output: (&Tensor, &Tensor),
        beam_dim: usize,
    ) -> Result<(StudentPlan, Tensor)> {
        let mut pack = Packer::default();
        let input = pack.affine(input.0, Some(input.1))?;
        let blocks = blocks
            .iter()
            .map(|[a, b]| {
                Ok(BlockPlan {
                    fc1: pack.affine(a.0, Some(a.1))?,
                    fc2: pack.affine(b.0, Some(b.1))?,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        let output = pack.affine(output.0, Some(output.1))?;
        if input.inp < beam_dim {
            candle_core::bail!(
                "student op: input layer takes {} values, fewer than the beam's {beam_dim}",
                input.inp
            );
        }
        let plan = StudentPlan {
            code_dim: input.inp - beam_dim,
            input,
            blocks,
            output,
            beam_dim,
            n_params: pack.len(),
        };
        Ok((plan, pack.tensor()?))
    }
}

/// What the forward keeps for the backward: the network input and, per layer, its output.
#[derive(Debug, Default)]
struct Stash {
    /// `[n, beam_dim + code_dim]`.
    x: Vec<f32>,
    /// The input layer's output, then each block's hidden and output rows, in order.
    layers: Vec<Vec<f32>>,
}

/// The op: plan, and the stash of one forward.
#[derive(Debug)]
pub struct StudentOp {
    pub plan: StudentPlan,
    /// Keep activations for a backward pass (training).
    pub keep: bool,
    stash: Mutex<Option<Stash>>,
}

impl StudentOp {
    /// An op for `plan`; `keep` activations when a backward pass will follow.
    pub fn new(plan: StudentPlan, keep: bool) -> StudentOp {
        StudentOp {
            plan,
            keep,
            stash: Mutex::new(None),
        }
    }

    /// The forward pass on raw slices: returns the raw outputs `[n, 3 M]` and the stash.
    fn run(&self, beams: &[f32], codes: &[f32], params: &[f32], n: usize) -> (Vec<f32>, Stash) {
        let plan = &self.plan;
        let x = input_rows(plan, beams, codes, n);
        let mut stash = Stash::default();
        let inp = &plan.input;
        let mut h = take_buffer(n * inp.out);
        linear_forward(
            &x,
            n,
            inp.inp,
            weight(params, inp),
            inp.out,
            &bias_or_zero(params, inp),
            Addend::Row,
            true,
            &mut h,
        );
        for block in &plan.blocks {
            let (f1, f2) = (&block.fc1, &block.fc2);
            let mut a = take_buffer(n * f1.out);
            linear_forward(
                &h,
                n,
                f1.inp,
                weight(params, f1),
                f1.out,
                &bias_or_zero(params, f1),
                Addend::Row,
                true,
                &mut a,
            );
            let mut y = take_buffer(n * f2.out);
            linear_forward_residual(
                &a,
                n,
                f2.inp,
                weight(params, f2),
                f2.out,
                &bias_or_zero(params, f2),
                &h,
                true,
                &mut y,
            );
            let h_in = std::mem::replace(&mut h, y);
            if self.keep {
                stash.layers.push(h_in);
                stash.layers.push(a);
            } else {
                give_buffer(h_in);
                give_buffer(a);
            }
        }
        let o = &plan.output;
        let mut out = vec![0.0f32; n * o.out];
        linear_forward(
            &h,
            n,
            o.inp,
            weight(params, o),
            o.out,
            &bias_or_zero(params, o),
            Addend::Row,
            false,
            &mut out,
        );
        if self.keep {
            stash.layers.push(h);
            stash.x = x;
        } else {
            give_buffer(h);
            give_buffer(x);
        }
        (out, stash)
    }
}

/// The input layer's rows, `[n, beam_dim + code_dim]`: each beam's encoding followed by
/// its audio code.
fn input_rows(plan: &StudentPlan, beams: &[f32], codes: &[f32], n: usize) -> Vec<f32> {
    let (b, c) = (plan.beam_dim, plan.code_dim);
    let mut x = take_buffer(n * (b + c));
    for ((row, beam), code) in x
        .chunks_exact_mut(b + c)
        .zip(beams.chunks_exact(b.max(1)))
        .zip(codes.chunks_exact(c.max(1)))
    {
        row[..b].copy_from_slice(beam);
        row[b..].copy_from_slice(code);
    }
    x
}

impl CustomOp3 for StudentOp {
    fn name(&self) -> &'static str {
        "nldf-fused-student"
    }

    fn cpu_fwd(
        &self,
        beams_storage: &CpuStorage,
        beams_layout: &Layout,
        codes_storage: &CpuStorage,
        codes_layout: &Layout,
        params_storage: &CpuStorage,
        params_layout: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let plan = &self.plan;
        let (n, b) = beams_layout.shape().dims2()?;
        let (n2, c) = codes_layout.shape().dims2()?;
        if b != plan.beam_dim || c != plan.code_dim || n2 != n {
            candle_core::bail!(
                "student op: beams [{n}, {b}] and codes [{n2}, {c}] do not fit the plan's [n, {}] and [n, {}]",
                plan.beam_dim,
                plan.code_dim
            );
        }
        if params_layout.shape().elem_count() != plan.n_params {
            candle_core::bail!(
                "student op: {} parameters given, the plan needs {}",
                params_layout.shape().elem_count(),
                plan.n_params
            );
        }
        let beams = contiguous(beams_storage, beams_layout, "beams")?;
        let codes = contiguous(codes_storage, codes_layout, "codes")?;
        let params = contiguous(params_storage, params_layout, "params")?;
        let (out, stash) = self.run(beams, codes, params, n);
        if self.keep {
            *self
                .stash
                .lock()
                .map_err(|_| candle_core::Error::Msg("student op stash poisoned".into()))? =
                Some(stash);
        }
        Ok((CpuStorage::F32(out), Shape::from((n, plan.output.out))))
    }

    fn bwd(
        &self,
        beams: &Tensor,
        codes: &Tensor,
        params: &Tensor,
        _out: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        let mut stash = self
            .stash
            .lock()
            .map_err(|_| candle_core::Error::Msg("student op stash poisoned".into()))?
            .take()
            .ok_or_else(|| {
                candle_core::Error::Msg("student op: backward without a kept forward".into())
            })?;
        let plan = &self.plan;
        let n = beams.dim(0)?;
        let dev = beams.device();
        let mut dp = vec![0.0f32; plan.n_params];
        let mut d_codes = vec![0.0f32; n * plan.code_dim];
        with_data(grad, "grad", |g| {
            with_data(params, "params", |p| {
                let o = &plan.output;
                let missing = || candle_core::Error::Msg("student op: empty stash".into());
                // out = h W_o^T + b_o
                let mut g_out = g.to_vec();
                let db = relu_backward(&mut g_out, &[], n, o.out, false);
                let h_last = stash.layers.pop().ok_or_else(missing)?;
                accumulate_affine(&mut dp, o, &g_out, &h_last, n, Some(&db));
                let mut g_h = take_buffer(n * o.inp);
                matmul(&g_out, n, o.out, weight(p, o), o.inp, &mut g_h);
                // Blocks, last first: y = relu(a W_2^T + b_2 + h), a = relu(h W_1^T + b_1).
                let mut y = h_last;
                for block in plan.blocks.iter().rev() {
                    let (f1, f2) = (&block.fc1, &block.fc2);
                    let a = stash.layers.pop().ok_or_else(missing)?;
                    let h = stash.layers.pop().ok_or_else(missing)?;
                    let db2 = relu_backward(&mut g_h, &y, n, f2.out, true);
                    accumulate_affine(&mut dp, f2, &g_h, &a, n, Some(&db2));
                    let mut g_a = take_buffer(n * f2.inp);
                    matmul(&g_h, n, f2.out, weight(p, f2), f2.inp, &mut g_a);
                    let db1 = relu_backward(&mut g_a, &a, n, f1.out, true);
                    accumulate_affine(&mut dp, f1, &g_a, &h, n, Some(&db1));
                    let mut g_in = take_buffer(n * f1.inp);
                    matmul_add(&g_a, n, f1.out, weight(p, f1), f1.inp, &g_h, &mut g_in);
                    give_buffer(g_a);
                    give_buffer(std::mem::replace(&mut g_h, g_in));
                    give_buffer(a);
                    give_buffer(std::mem::replace(&mut y, h));
                }
                // h_0 = relu(x W_in^T + b_in); the codes' gradient is g W_in[:, beam..].
                let i = &plan.input;
                let db0 = relu_backward(&mut g_h, &y, n, i.out, true);
                accumulate_affine(&mut dp, i, &g_h, &stash.x, n, Some(&db0));
                let (b, c) = (plan.beam_dim, plan.code_dim);
                let w_codes: Vec<f32> = weight(p, i)
                    .chunks_exact(i.inp)
                    .flat_map(|row| row[b..b + c].iter().copied())
                    .collect();
                matmul(&g_h, n, i.out, &w_codes, c, &mut d_codes);
                give_buffer(g_h);
                give_buffer(y);
                Ok(())
            })
        })?;
        give_buffer(std::mem::take(&mut stash.x));
        let d_params = Tensor::from_vec(dp, params.shape(), dev)?;
        let d_codes = Tensor::from_vec(d_codes, codes.shape(), dev)?;
        Ok((None, Some(d_codes), Some(d_params)))
    }
}
