//! The student's loss (paper Eq. 6, 8 and 9): the pixel's squared error against the ground
//! truth plus lambda times the segments' squared error against the teacher's Eq. 5 segment
//! colours, per ray, both as means over the colour channels. A student with opacity also
//! distils the teacher's accumulated weight, inside the same lambda term.

use candle_core::{D, Result, Tensor};

/// Per-ray losses of a batch.
#[derive(Debug, Clone)]
pub struct RayLosses {
    /// Eq. 9 per ray: `|c - c_gt|^2 / 3 + lambda (sum_i |c_i - c~_i|^2 / 3 + (a - a~)^2)`,
    /// `[n]` (the opacity term only for a student with opacity).
    pub per_ray: Tensor,
    /// Eq. 8's squared pixel error per ray, summed over the channels, `[n]`.
    pub pixel_sq: Tensor,
}

/// The teacher's answer for a batch of rays, what the student distils.
#[derive(Debug, Clone, Copy)]
pub struct TeacherTargets<'a> {
    /// Eq. 5 segment colours, `[n, m, 3]`.
    pub segments: &'a Tensor,
    /// Accumulated weight `sum_k w_k` of the samples inside the head's bounds, `[n, 1]`;
    /// for a student with opacity.
    pub opacity: Option<&'a Tensor>,
}

/// Eq. 9 per ray: the pixel loss (Eq. 8) of `pixels` against `truth`, plus, with `targets`
/// (distillation), `lambda` times the segment loss (Eq. 6) of `segments` against them and,
/// where both sides have one, the squared error of the opacity.
///
/// # Shapes
/// - `pixels`, `truth`: `[n, 3]`; `segments`: `[n, m, 3]`; `opacity`: `[n, 1]`
pub fn distillation_loss(
    pixels: &Tensor,
    truth: &Tensor,
    segments: &Tensor,
    opacity: Option<&Tensor>,
    targets: Option<TeacherTargets>,
    lambda: f64,
) -> Result<RayLosses> {
    let pixel_sq = (pixels - truth)?.sqr()?.sum(D::Minus1)?;
    let mut per_ray = (pixel_sq.clone() / 3.0)?;
    if let Some(targets) = targets {
        let seg_sq = (segments - targets.segments)?.sqr()?.sum((1, 2))?;
        per_ray = (per_ray + (seg_sq * (lambda / 3.0))?)?;
        if let (Some(a), Some(t)) = (opacity, targets.opacity) {
            let a_sq = (a - t)?.sqr()?.sum(D::Minus1)?;
            per_ray = (per_ray + (a_sq * lambda)?)?;
        }
    }
    Ok(RayLosses { per_ray, pixel_sq })
}
