//! The student's loss (paper Eq. 6, 8 and 9): the pixel's squared error against the ground
//! truth plus lambda times the segments' squared error against the teacher's Eq. 5 segment
//! colours, per ray, both as means over the colour channels. The student also distils the
//! teacher's accumulated weight, its opacity, inside the same lambda term.

use candle_core::{D, Result, Tensor};

/// Per-ray losses of a batch.
#[derive(Debug, Clone)]
pub struct RayLosses {
    /// Eq. 9 per ray: `|c - c_gt|^2 / 3 + lambda (sum_i |c_i - c~_i|^2 / 3 + KL(a~ | a))`,
    /// `[n]`.
    pub per_ray: Tensor,
    /// Eq. 8's squared pixel error per ray, summed over the channels, `[n]`.
    pub pixel_sq: Tensor,
}

/// The teacher's answer for a batch of rays, what the student distils.
#[derive(Debug, Clone, Copy)]
pub struct TeacherTargets<'a> {
    /// Eq. 5 segment colours, `[n, m, 3]`.
    pub segments: &'a Tensor,
    /// Accumulated weight `sum_k w_k` of the samples inside the head's bounds, `[n, 1]`.
    pub opacity: &'a Tensor,
}

/// Eq. 9 per ray: the pixel loss (Eq. 8) of `pixels` against `truth`, plus, with `targets`
/// (distillation), `lambda` times the segment loss (Eq. 6) of `segments` against them and
/// the opacity's divergence from the teacher's ([`opacity_divergence`], from the student's
/// opacity `logit`).
///
/// # Shapes
/// - `pixels`, `truth`: `[n, 3]`; `segments`: `[n, m, 3]`; `logit`: `[n, 1]`
pub fn distillation_loss(
    pixels: &Tensor,
    truth: &Tensor,
    segments: &Tensor,
    logit: &Tensor,
    targets: Option<TeacherTargets>,
    lambda: f64,
) -> Result<RayLosses> {
    let pixel_sq = (pixels - truth)?.sqr()?.sum(D::Minus1)?;
    let mut per_ray = (pixel_sq.clone() / 3.0)?;
    if let Some(targets) = targets {
        let seg_sq = (segments - targets.segments)?.sqr()?.sum((1, 2))?;
        per_ray = (per_ray + (seg_sq * (lambda / 3.0))?)?;
        per_ray = (per_ray + (opacity_divergence(logit, targets.opacity)? * lambda)?)?;
    }
    Ok(RayLosses { per_ray, pixel_sq })
}

/// The divergence of the student's opacity `a = sigmoid(z)` from the teacher's `t`, both
/// read as the probability that the ray meets the head: the binary cross-entropy less the
/// target's own entropy, `softplus(z) - t z - H(t)`, which is 0 where `a = t` and, unlike a
/// squared error, keeps pulling an opacity towards 0 (or 1) with a gradient `a - t` in `z`,
/// so that rays the head does not cover end up leaving the background untouched.
///
/// # Shapes
/// - `z`, `t`: `[n, 1]`; returns `[n]`
pub fn opacity_divergence(z: &Tensor, t: &Tensor) -> Result<Tensor> {
    // softplus(z) = max(z, 0) + ln(1 + exp(-|z|)), stable for any z.
    let softplus = (z.relu()? + (z.abs()?.neg()?.exp()? + 1.0)?.log()?)?;
    let cross = (softplus - (t * z)?)?;
    // H(t) from the targets alone (no gradient), with 0 ln 0 = 0.
    let tv: Vec<f32> = t.flatten_all()?.to_vec1()?;
    let h: Vec<f32> = tv
        .iter()
        .map(|&p| {
            let p = p.clamp(0.0, 1.0);
            let term = |q: f32| if q > 0.0 { -q * q.ln() } else { 0.0 };
            term(p) + term(1.0 - p)
        })
        .collect();
    let h = Tensor::from_vec(h, t.shape(), t.device())?;
    (cross - h)?.sum(D::Minus1)
}
