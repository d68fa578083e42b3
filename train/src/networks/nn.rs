//! Small layer helpers shared by the teacher and the student: a dense layer whose weights
//! follow candle's `Linear` layout (`weight` `[out, in]`, `bias` `[out]`), and seeded
//! initialisation (candle's CPU random generator cannot be seeded).

use candle_core::{DType, Device, Result, Tensor, Var};
use candle_nn::{VarBuilder, VarMap};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A dense layer `y = x W^T + b`.
#[derive(Debug, Clone)]
pub struct Dense {
    pub weight: Tensor,
    pub bias: Option<Tensor>,
}

/// Builds a [`Dense`] layer `in_dim -> out_dim` under `vb` (`weight`, and `bias` when
/// `bias`).
pub fn dense(in_dim: usize, out_dim: usize, bias: bool, vb: VarBuilder) -> Result<Dense> {
    let bound = 1.0 / (in_dim as f64).sqrt();
    let init = candle_nn::Init::Uniform {
        lo: -bound,
        up: bound,
    };
    let weight = vb.get_with_hints((out_dim, in_dim), "weight", init)?;
    let bias = if bias {
        Some(vb.get_with_hints(out_dim, "bias", init)?)
    } else {
        None
    };
    Ok(Dense { weight, bias })
}

impl Dense {
    /// `x W^T + b`.
    ///
    /// # Shapes
    /// - `x`: `[n, in]`; returns `[n, out]`
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let y = x.matmul(&self.weight.t()?)?;
        match &self.bias {
            Some(b) => y.broadcast_add(b),
            None => Ok(y),
        }
    }
}

/// Sets every variable of `varmap` to seeded values, in name order: weights and biases
/// uniform in `±1 / sqrt(fan_in)` (PyTorch's default for `Linear` and `Conv1d`, which
/// AD-NeRF and R2L train with), where `fan_in` is the product of a weight's trailing
/// dimensions and a bias takes its sibling weight's.
pub fn init_seeded(varmap: &VarMap, seed: u64) -> Result<()> {
    let data = varmap
        .data()
        .lock()
        .map_err(|_| candle_core::Error::Msg("variable map lock poisoned".into()))?;
    let mut names: Vec<&String> = data.keys().collect();
    names.sort();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for name in names {
        let var = &data[name];
        let fan_in = match name.strip_suffix("bias") {
            Some(prefix) => data
                .get(&format!("{prefix}weight"))
                .map(|w| w.dims().iter().skip(1).product::<usize>())
                .unwrap_or(1),
            None => var.dims().iter().skip(1).product::<usize>(),
        };
        set_uniform(var, fan_in, &mut rng)?;
    }
    Ok(())
}

/// Sets `var` to values drawn from `rng`, uniform in `±1 / sqrt(fan_in)`.
pub fn set_uniform(var: &Var, fan_in: usize, rng: &mut ChaCha8Rng) -> Result<()> {
    set_uniform_within(var, 1.0 / (fan_in.max(1) as f32).sqrt(), rng)
}

/// Sets `var` to values drawn from `rng`, uniform in `±bound`.
pub fn set_uniform_within(var: &Var, bound: f32, rng: &mut ChaCha8Rng) -> Result<()> {
    let values: Vec<f32> = (0..var.elem_count())
        .map(|_| rng.random_range(-bound..bound))
        .collect();
    var.set(&Tensor::from_vec(values, var.shape(), var.device())?)
}

/// A fresh variable map and a builder over it (f32, CPU).
pub fn new_varmap() -> (VarMap, VarBuilder<'static>) {
    let varmap = VarMap::new();
    let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
    (varmap, vb)
}

/// The variables of `varmap` sorted by name.
pub fn sorted_vars(varmap: &VarMap) -> Result<Vec<(String, Var)>> {
    let data = varmap
        .data()
        .lock()
        .map_err(|_| candle_core::Error::Msg("variable map lock poisoned".into()))?;
    let mut vars: Vec<(String, Var)> = data.iter().map(|(k, v)| (k.clone(), v.clone())).collect();
    vars.sort_by(|a, b| a.0.cmp(&b.0));
    Ok(vars)
}

/// The variables of `varmap` sorted by name, each with its learning-rate scale for
/// `Adam::new` (the trainers' optimizer): the scale of the first `(prefix, scale)` whose prefix starts
/// the name, 1 where none does.
pub fn scaled_vars(varmap: &VarMap, scales: &[(&str, f64)]) -> Result<Vec<(String, Var, f64)>> {
    Ok(sorted_vars(varmap)?
        .into_iter()
        .map(|(name, var)| {
            let s = scales
                .iter()
                .find(|(prefix, _)| name.starts_with(prefix))
                .map_or(1.0, |&(_, scale)| scale);
            (name, var, s)
        })
        .collect())
}

/// A 1-D convolution computed as patches times a matrix (im2col), with candle's `Conv1d`
/// weight layout (`weight` `[out, in, k]`, `bias` `[out]`). candle 0.11's own `conv1d`
/// backward underflows for strided convolutions over short inputs (AudioNet's 2 -> 1 step);
/// this one is built from ops whose gradients are exact.
#[derive(Debug, Clone)]
pub struct Conv1d {
    pub weight: Tensor,
    pub bias: Tensor,
    pub stride: usize,
    pub padding: usize,
}

/// Builds a [`Conv1d`] `in_dim -> out_dim` with kernel `k` under `vb`.
pub fn conv1d(
    in_dim: usize,
    out_dim: usize,
    k: usize,
    stride: usize,
    padding: usize,
    vb: VarBuilder,
) -> Result<Conv1d> {
    let bound = 1.0 / ((in_dim * k) as f64).sqrt();
    let init = candle_nn::Init::Uniform {
        lo: -bound,
        up: bound,
    };
    Ok(Conv1d {
        weight: vb.get_with_hints((out_dim, in_dim, k), "weight", init)?,
        bias: vb.get_with_hints(out_dim, "bias", init)?,
        stride: stride.max(1),
        padding,
    })
}

impl Conv1d {
    /// Output length for an input of length `l`.
    pub fn out_len(&self, l: usize) -> usize {
        let k = self.weight.dims()[2];
        (l + 2 * self.padding).saturating_sub(k) / self.stride + 1
    }

    /// The convolution.
    ///
    /// # Shapes
    /// - `x`: `[n, in, l]`; returns `[n, out, out_len(l)]`
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let (n, c, l) = x.dims3()?;
        let (out, _, k) = self.weight.dims3()?;
        let l_out = self.out_len(l);
        let s = self.stride;
        // Zero padding, plus enough on the right that every tap can take l_out * s values.
        let right = (l_out * s + k).saturating_sub(l + self.padding);
        let padded = x.pad_with_zeros(2, self.padding, right)?;
        let mut taps = Vec::with_capacity(k);
        for j in 0..k {
            let t = padded.narrow(2, j, l_out * s)?;
            let t = if s > 1 {
                t.reshape((n, c, l_out, s))?.narrow(3, 0, 1)?.squeeze(3)?
            } else {
                t
            };
            taps.push(t);
        }
        let patches = Tensor::stack(&taps, 2)? // [n, c, k, l_out]
            .reshape((n, c * k, l_out))?
            .transpose(1, 2)?
            .reshape((n * l_out, c * k))?;
        let w = self.weight.reshape((out, c * k))?;
        patches
            .matmul(&w.t()?)?
            .broadcast_add(&self.bias)?
            .reshape((n, l_out, out))?
            .transpose(1, 2)
    }
}
