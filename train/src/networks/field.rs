//! The teacher's field (AD-NeRF's head NeRF): encoded points and the audio code -> density
//! and a feature; the feature and the encoded view direction -> colour. Nothing here knows
//! rays or compositing.
//!
//! The audio code is the same for every sample of a ray, so its share of the first layer
//! (and of each skip layer) is computed once per ray and broadcast over the ray's samples:
//! the same function as AD-NeRF's concatenation `[PE(x), a]`, at a fraction of the cost.
//! The view direction enters the colour head the same way.

use candle_core::{Result, Tensor};
use candle_nn::VarBuilder;

use crate::networks::nn::{Dense, dense};
use crate::networks::teacher_config::TeacherConfig;
use crate::ops::field_op::{FieldOp, FieldPlan, TrunkStep};
use crate::ops::op_base::Packer;

/// One trunk layer: the hidden input, plus the point encoding and the audio code where the
/// network feeds its input in (the first layer and after each skip).
#[derive(Debug, Clone)]
struct TrunkLayer {
    hidden: Option<Dense>,
    points: Option<Dense>,
    audio: Option<Dense>,
}

/// AD-NeRF's head NeRF.
#[derive(Debug, Clone)]
pub struct TeacherField {
    trunk: Vec<TrunkLayer>,
    density: Dense,
    feature: Dense,
    color_feature: Dense,
    color_dir: Dense,
    rgb: Dense,
    /// Its points come from a learned encoding (the grid teacher's hash grid): the backward
    /// gives them their gradient.
    learned_points: bool,
}

/// Builds a [`TeacherField`] under `vb`, layer by layer as
/// [`TeacherConfig::field_layers`] lists them: `trunk.{i}.{hidden,points,audio}`,
/// `density`, `feature`, `color_feature`, `color_dir`, `rgb`.
pub fn teacher_field(cfg: &TeacherConfig, vb: VarBuilder) -> Result<TeacherField> {
    let mut built = std::collections::HashMap::new();
    for l in cfg.field_layers() {
        let layer = dense(l.fan_in, l.fan_out, l.bias, vb.pp(&l.name))?;
        built.insert(l.name, layer);
    }
    // Each trunk layer's inputs are those the description lists for it.
    let trunk = (0..cfg.depth)
        .map(|i| {
            let mut input = |kind: &str| built.remove(&format!("trunk.{i}.{kind}"));
            TrunkLayer {
                hidden: input("hidden"),
                points: input("points"),
                audio: input("audio"),
            }
        })
        .collect();
    let mut take = |name: &str| {
        built
            .remove(name)
            .ok_or_else(|| candle_core::Error::Msg(format!("the field has no layer `{name}`")))
    };
    Ok(TeacherField {
        trunk,
        density: take("density")?,
        feature: take("feature")?,
        color_feature: take("color_feature")?,
        color_dir: take("color_dir")?,
        rgb: take("rgb")?,
        learned_points: cfg.grid.is_some(),
    })
}

/// `log(1 + exp(x))`, written so that it neither overflows nor loses its gradient: the
/// density activation (a ReLU, as AD-NeRF uses, can switch a young field off everywhere).
pub fn softplus(x: &Tensor) -> Result<Tensor> {
    x.relu()? + (x.abs()?.neg()?.exp()? + 1.0)?.log()?
}

/// `x W^T + b` of a per-ray layer, plus `extra` when given.
fn per_ray(layer: &Dense, x: &Tensor, extra: Option<&Tensor>) -> Result<Tensor> {
    let y = layer.forward(x)?;
    match extra {
        Some(e) => y.broadcast_add(e),
        None => Ok(y),
    }
}

/// Adds a per-ray term to every sample of its ray.
///
/// # Shapes
/// - `per_sample`: `[n_rays * n_samples, w]`; `per_ray`: `[n_rays, w]`
fn add_per_ray(per_sample: &Tensor, per_ray: &Tensor, n_samples: usize) -> Result<Tensor> {
    let (n, w) = per_sample.dims2()?;
    per_sample
        .reshape((n / n_samples, n_samples, w))?
        .broadcast_add(&per_ray.unsqueeze(1)?)?
        .reshape((n, w))
}

impl TeacherField {
    /// Raw densities and colours of every sample, through the fused op ([`FieldOp`]): one
    /// candle op for the whole per-sample network. With `train`, it keeps what its backward
    /// needs.
    ///
    /// # Shapes
    /// - `points`: `[n_rays * n_samples, pos_dim]` encoded sample positions
    /// - `codes`: `[n_rays, audio_dim]` audio code of each ray's frame
    /// - `dirs`: `[n_rays, dir_dim]` encoded view directions
    /// - returns densities `[n_rays, n_samples]` (softplus, so >= 0) and colours
    ///   `[n_rays, n_samples, 3]` (sigmoid)
    pub fn forward(
        &self,
        points: &Tensor,
        codes: &Tensor,
        dirs: &Tensor,
        n_samples: usize,
        train: bool,
    ) -> Result<(Tensor, Tensor)> {
        let n_rays = codes.dim(0)?;
        let mut pack = Packer::default();
        let mut ray_terms = Vec::new();
        let mut ray_width = 0;
        let mut trunk = Vec::with_capacity(self.trunk.len());
        for layer in &self.trunk {
            let fed = matches!((&layer.points, &layer.audio), (Some(_), Some(_)));
            // The biases of fed layers travel with their per-ray term.
            let hidden = match &layer.hidden {
                Some(h) => Some(pack.affine(&h.weight, h.bias.as_ref().filter(|_| !fed))?),
                None => None,
            };
            let (points_affine, ray) = match (&layer.points, &layer.audio) {
                (Some(p), Some(a)) => {
                    let bias = match (&layer.hidden, &p.bias) {
                        (Some(h), _) => h.bias.clone(),
                        (None, b) => b.clone(),
                    };
                    let term = per_ray(a, codes, bias.as_ref())?;
                    let off = ray_width;
                    ray_width += term.dim(1)?;
                    ray_terms.push(term);
                    (Some(pack.affine(&p.weight, None)?), Some(off))
                }
                _ => (None, None),
            };
            trunk.push(TrunkStep {
                hidden,
                points: points_affine,
                ray,
            });
        }
        let density = pack.affine(&self.density.weight, self.density.bias.as_ref())?;
        let feature = pack.affine(&self.feature.weight, self.feature.bias.as_ref())?;
        let color = pack.affine(&self.color_feature.weight, None)?;
        let color_term = per_ray(&self.color_dir, dirs, self.color_feature.bias.as_ref())?;
        let color_ray = ray_width;
        ray_width += color_term.dim(1)?;
        ray_terms.push(color_term);
        let rgb = pack.affine(&self.rgb.weight, self.rgb.bias.as_ref())?;
        let plan = FieldPlan {
            trunk,
            density,
            feature,
            color,
            color_ray,
            rgb,
            n_samples,
            ray_width,
            n_params: pack.len(),
        };
        let params = pack.tensor()?;
        let rays = Tensor::cat(&ray_terms, 1)?;
        let op = FieldOp::new(plan, train).with_points_grad(train && self.learned_points);
        let points = points.contiguous()?;
        let raw = if train {
            points.apply_op3(&params, &rays, op)?
        } else {
            points.apply_op3_no_bwd(&params, &rays, &op)?
        };
        let density = softplus(&raw.narrow(1, 0, 1)?)?.reshape((n_rays, n_samples))?;
        let rgb =
            candle_nn::ops::sigmoid(&raw.narrow(1, 1, 3)?)?.reshape((n_rays, n_samples, 3))?;
        Ok((density, rgb))
    }

    /// The same function as [`TeacherField::forward`] built from plain candle ops: the
    /// reference the fused op is tested against.
    pub fn forward_reference(
        &self,
        points: &Tensor,
        codes: &Tensor,
        dirs: &Tensor,
        n_samples: usize,
    ) -> Result<(Tensor, Tensor)> {
        let n_rays = codes.dim(0)?;
        let mut h: Option<Tensor> = None;
        for layer in &self.trunk {
            let mut x = match (&layer.hidden, &h) {
                (Some(l), Some(h)) => Some(l.forward(h)?),
                _ => None,
            };
            if let (Some(p), Some(a)) = (&layer.points, &layer.audio) {
                let fed = p.forward(points)?;
                let fed = match x {
                    Some(x) => (x + fed)?,
                    None => fed,
                };
                x = Some(add_per_ray(&fed, &a.forward(codes)?, n_samples)?);
            }
            h = Some(
                x.ok_or_else(|| candle_core::Error::Msg("trunk layer without input".into()))?
                    .relu()?,
            );
        }
        let h = h.ok_or_else(|| candle_core::Error::Msg("teacher trunk is empty".into()))?;
        let density = softplus(&self.density.forward(&h)?)?.reshape((n_rays, n_samples))?;
        let feature = self.feature.forward(&h)?;
        let c = add_per_ray(
            &self.color_feature.forward(&feature)?,
            &self.color_dir.forward(dirs)?,
            n_samples,
        )?
        .relu()?;
        let rgb =
            candle_nn::ops::sigmoid(&self.rgb.forward(&c)?)?.reshape((n_rays, n_samples, 3))?;
        Ok((density, rgb))
    }
}
