//! Adam (Kingma and Ba) over candle variables, with its state exposed so that checkpoints
//! can save it and a resumed run continues bit for bit. Each variable may have its own
//! learning-rate scale (AD-NeRF trains AudioAttNet at 5x the base rate), and a variable
//! without a gradient this step (a switched-off branch) is left untouched.

use std::collections::HashMap;

use candle_core::{Tensor, Var, backprop::GradStore};
use rayon::prelude::*;

use crate::error::{Error, Result};

/// Adam's hyper-parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdamParams {
    pub beta1: f64,
    pub beta2: f64,
    pub eps: f64,
}

/// One variable and its moments.
#[derive(Debug)]
struct Slot {
    name: String,
    var: Var,
    lr_scale: f64,
    m: Vec<f32>,
    v: Vec<f32>,
    /// Updates this variable has had (bias correction counts per variable, so that a branch
    /// switched on late starts with corrected moments).
    t: u64,
}

/// Adam over a fixed list of variables.
#[derive(Debug)]
pub struct Adam {
    params: AdamParams,
    slots: Vec<Slot>,
}

impl Adam {
    /// Adam over `vars` (name, variable, learning-rate scale), moments at zero.
    pub fn new(vars: Vec<(String, Var, f64)>, params: AdamParams) -> Adam {
        let slots = vars
            .into_iter()
            .map(|(name, var, lr_scale)| {
                let n = var.elem_count();
                Slot {
                    name,
                    var,
                    lr_scale,
                    m: vec![0.0; n],
                    v: vec![0.0; n],
                    t: 0,
                }
            })
            .collect();
        Adam { params, slots }
    }

    /// One update at learning rate `lr` from the gradients in `grads`. A gradient holding a
    /// NaN or infinite value is refused before any variable changes, with
    /// [`Error::NonFinite`] naming the variable.
    pub fn step(&mut self, grads: &GradStore, lr: f64) -> Result<()> {
        let AdamParams { beta1, beta2, eps } = self.params;
        let mut flat: Vec<Option<Vec<f32>>> = Vec::with_capacity(self.slots.len());
        for slot in &self.slots {
            let g = match grads.get(slot.var.as_tensor()) {
                Some(grad) => grad.flatten_all()?.to_vec1::<f32>()?,
                None => {
                    flat.push(None);
                    continue;
                }
            };
            if g.par_iter().any(|v| !v.is_finite()) {
                return Err(Error::NonFinite(format!(
                    "the gradient of `{}` holds a NaN or infinite value",
                    slot.name
                )));
            }
            flat.push(Some(g));
        }
        for (slot, g) in self.slots.iter_mut().zip(flat) {
            let Some(g) = g else { continue };
            let mut theta: Vec<f32> = slot.var.as_tensor().flatten_all()?.to_vec1()?;
            slot.t += 1;
            let t = slot.t as i32;
            let step = (lr * slot.lr_scale) as f32;
            let c1 = 1.0 / (1.0 - beta1.powi(t)) as f32;
            let c2 = 1.0 / (1.0 - beta2.powi(t)) as f32;
            let (b1, b2, eps) = (beta1 as f32, beta2 as f32, eps as f32);
            theta
                .par_chunks_mut(4096)
                .zip(slot.m.par_chunks_mut(4096))
                .zip(slot.v.par_chunks_mut(4096))
                .zip(g.par_chunks(4096))
                .for_each(|(((th, m), v), g)| {
                    for i in 0..th.len() {
                        m[i] = b1 * m[i] + (1.0 - b1) * g[i];
                        v[i] = b2 * v[i] + (1.0 - b2) * g[i] * g[i];
                        th[i] -= step * (m[i] * c1) / ((v[i] * c2).sqrt() + eps);
                    }
                });
            let shape = slot.var.shape().clone();
            slot.var
                .set(&Tensor::from_vec(theta, shape, slot.var.device())?)?;
        }
        Ok(())
    }

    /// The state as named tensors: `m.<name>`, `v.<name>` and `t.<name>` (a one-element
    /// f64 tensor holding the update count).
    pub fn state(&self) -> candle_core::Result<HashMap<String, Tensor>> {
        let mut out = HashMap::new();
        for s in &self.slots {
            let dev = s.var.device();
            out.insert(
                format!("m.{}", s.name),
                Tensor::from_slice(&s.m, s.var.shape(), dev)?,
            );
            out.insert(
                format!("v.{}", s.name),
                Tensor::from_slice(&s.v, s.var.shape(), dev)?,
            );
            out.insert(
                format!("t.{}", s.name),
                Tensor::from_slice(&[s.t as f64], 1, dev)?,
            );
        }
        Ok(out)
    }

    /// Restores a state written by [`Adam::state`]; every variable must be present with its
    /// shape.
    pub fn load_state(&mut self, state: &HashMap<String, Tensor>) -> candle_core::Result<()> {
        for s in &mut self.slots {
            let get = |key: String| {
                state.get(&key).ok_or_else(|| {
                    candle_core::Error::Msg(format!("optimizer state lacks `{key}`"))
                })
            };
            let m = get(format!("m.{}", s.name))?;
            let v = get(format!("v.{}", s.name))?;
            if m.dims() != s.var.dims() || v.dims() != s.var.dims() {
                candle_core::bail!(
                    "optimizer state of `{}` has shape {:?}, the variable {:?}",
                    s.name,
                    m.dims(),
                    s.var.dims()
                );
            }
            s.m = m.flatten_all()?.to_vec1()?;
            s.v = v.flatten_all()?.to_vec1()?;
            let t: Vec<f64> = get(format!("t.{}", s.name))?.flatten_all()?.to_vec1()?;
            s.t = t.first().copied().unwrap_or(0.0) as u64;
        }
        Ok(())
    }
}
