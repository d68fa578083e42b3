//! Volume rendering in candle (Eq. 3-4) with the background as the last sample (AD-NeRF):
//! the colour left after the samples' weights is the background pixel's. Nothing here knows
//! the network or the rays.

use candle_core::{D, Result, Tensor};

/// Optical depth at which a sample is opaque to f32 precision (`exp(-100)` is 4e-44).
pub const MAX_TAU: f32 = 100.0;

/// Compositing results of a batch of rays.
#[derive(Debug, Clone)]
pub struct Rendered {
    /// `[n_rays, 3]`: pixel colours.
    pub color: Tensor,
    /// `[n_rays, n_samples]`: sample weights `w_k = T_k (1 - exp(-sigma_k delta_k))`.
    pub weights: Tensor,
    /// `[n_rays]`: transmittance left after the last sample (the background's weight).
    pub transmittance: Tensor,
}

/// Composites samples front to back: `T_k = exp(-sum_{j<k} sigma_j delta_j)` computed from an
/// exclusive cumulative sum in log space, `w_k = T_k (1 - exp(-sigma_k delta_k))`,
/// `C = sum_k w_k c_k + T_N bg`. Densities are clamped at 0 and each optical depth
/// `sigma delta` at [`MAX_TAU`], so any finite input gives a finite colour.
///
/// # Shapes
/// - `densities`, `deltas`: `[n_rays, n_samples]`
/// - `colors`: `[n_rays, n_samples, 3]`
/// - `background`: `[n_rays, 3]`
pub fn composite(
    densities: &Tensor,
    deltas: &Tensor,
    colors: &Tensor,
    background: &Tensor,
) -> Result<Rendered> {
    // Optical depth per sample, capped where exp(-tau) is already 0 in f32, so that huge
    // densities or spacings never make inf - inf.
    let tau = densities.relu()?.mul(deltas)?.clamp(0f32, MAX_TAU)?;
    let (n_rays, n) = tau.dims2()?;
    // The exclusive sum is summed directly (not inclusive - tau, which cancels badly).
    let shifted = Tensor::cat(
        &[
            Tensor::zeros((n_rays, 1), tau.dtype(), tau.device())?,
            tau.narrow(1, 0, n - 1)?,
        ],
        1,
    )?;
    let exclusive = shifted.cumsum(1)?;
    let inclusive = (&exclusive + &tau)?;
    let transmittance = exclusive.neg()?.exp()?;
    let alpha = (1.0 - tau.neg()?.exp()?)?;
    let weights = transmittance.mul(&alpha)?;
    let left = inclusive.narrow(1, n - 1, 1)?.neg()?.exp()?;
    let color = weights
        .unsqueeze(2)?
        .broadcast_mul(colors)?
        .sum(1)?
        .add(&background.broadcast_mul(&left)?)?;
    Ok(Rendered {
        color,
        weights,
        transmittance: left.squeeze(D::Minus1)?,
    })
}
