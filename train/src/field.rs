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

use crate::config::TeacherConfig;
use crate::fused::{AddTo, fused_linear};
use crate::nn::{Dense, dense};

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
}

/// Builds a [`TeacherField`] under `vb`: `trunk.{i}.{hidden,points,audio}`, `density`,
/// `feature`, `color_feature`, `color_dir`, `rgb`.
pub fn teacher_field(cfg: &TeacherConfig, vb: VarBuilder) -> Result<TeacherField> {
    let (w, p, a) = (cfg.width, cfg.pos_dim(), cfg.audio.dim);
    let mut trunk = Vec::with_capacity(cfg.depth);
    for i in 0..cfg.depth {
        let vb = vb.pp("trunk").pp(i);
        let fed = i == 0 || cfg.skips.contains(&(i - 1));
        trunk.push(TrunkLayer {
            hidden: if i > 0 {
                Some(dense(w, w, true, vb.pp("hidden"))?)
            } else {
                None
            },
            points: if fed {
                Some(dense(p, w, i == 0, vb.pp("points"))?)
            } else {
                None
            },
            audio: if fed {
                Some(dense(a, w, false, vb.pp("audio"))?)
            } else {
                None
            },
        });
    }
    Ok(TeacherField {
        trunk,
        density: dense(w, 1, true, vb.pp("density"))?,
        feature: dense(w, w, true, vb.pp("feature"))?,
        color_feature: dense(w, cfg.color_width, true, vb.pp("color_feature"))?,
        color_dir: dense(cfg.dir_dim(), cfg.color_width, false, vb.pp("color_dir"))?,
        rgb: dense(cfg.color_width, 3, true, vb.pp("rgb"))?,
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

/// The layer's bias, or zeros of its width.
fn bias_or_zeros(layer: &Dense) -> Result<Tensor> {
    match &layer.bias {
        Some(b) => Ok(b.clone()),
        None => Tensor::zeros(layer.weight.dim(0)?, layer.weight.dtype(), layer.weight.device()),
    }
}

impl TeacherField {
    /// Densities (softplus, so >= 0) and colours of every sample. Every per-sample layer
    /// runs as one fused op ([`fused_linear`]); the per-ray terms (audio code, view
    /// direction) enter as group addends.
    ///
    /// # Shapes
    /// - `points`: `[n_rays * n_samples, pos_dim]` encoded sample positions
    /// - `codes`: `[n_rays, audio_dim]` audio code of each ray's frame
    /// - `dirs`: `[n_rays, dir_dim]` encoded view directions
    /// - returns densities `[n_rays, n_samples]` and colours `[n_rays, n_samples, 3]`
    pub fn forward(
        &self,
        points: &Tensor,
        codes: &Tensor,
        dirs: &Tensor,
        n_samples: usize,
    ) -> Result<(Tensor, Tensor)> {
        let n_rays = codes.dim(0)?;
        let group = AddTo::Groups(n_samples);
        let mut h: Option<Tensor> = None;
        for layer in &self.trunk {
            let fed = match (&layer.points, &layer.audio) {
                (Some(p), Some(a)) => Some((p, a)),
                _ => None,
            };
            h = Some(match (&layer.hidden, h, fed) {
                // The first layer: points, plus the per-ray audio term and the bias.
                (None, _, Some((p, a))) => {
                    let ray = per_ray(a, codes, p.bias.as_ref())?;
                    fused_linear(points, &p.weight, &ray, group, true)?
                }
                // A skip layer: hidden + points + audio, summed before the ReLU.
                (Some(hid), Some(prev), Some((p, a))) => {
                    let ray = per_ray(a, codes, Some(&bias_or_zeros(hid)?))?;
                    let fed = fused_linear(points, &p.weight, &ray, group, false)?;
                    fused_linear(&prev, &hid.weight, &fed, AddTo::Each, true)?
                }
                (Some(hid), Some(prev), None) => {
                    fused_linear(&prev, &hid.weight, &bias_or_zeros(hid)?, AddTo::Every, true)?
                }
                _ => candle_core::bail!("teacher trunk layer without input"),
            });
        }
        let h = h.ok_or_else(|| candle_core::Error::Msg("teacher trunk is empty".into()))?;
        let raw = fused_linear(&h, &self.density.weight, &bias_or_zeros(&self.density)?, AddTo::Every, false)?;
        let density = softplus(&raw)?.reshape((n_rays, n_samples))?;
        let feature = fused_linear(&h, &self.feature.weight, &bias_or_zeros(&self.feature)?, AddTo::Every, false)?;
        let ray = per_ray(&self.color_dir, dirs, self.color_feature.bias.as_ref())?;
        let c = fused_linear(&feature, &self.color_feature.weight, &ray, group, true)?;
        let rgb = fused_linear(&c, &self.rgb.weight, &bias_or_zeros(&self.rgb)?, AddTo::Every, false)?;
        let rgb = candle_nn::ops::sigmoid(&rgb)?.reshape((n_rays, n_samples, 3))?;
        Ok((density, rgb))
    }
}
