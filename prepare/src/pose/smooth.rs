//! Temporal smoothing of head poses without lag: a centred, Gaussian-weighted local linear
//! fit over the neighbouring frames, rotations in the tangent space of the frame's own.
//!
//! For frame `i` at video index `n_i`, each neighbour `k` with `|n_k - n_i| <= radius` gets
//! the weight `exp(-(n_k - n_i)^2 / (2 sigma^2))`; the rotation offsets
//! `v_k = log(R_k R_i^T)` and the translations `t_k` are fitted by weighted least squares
//! with `a + b (n_k - n_i)` and the smoothed pose is `R_i' = exp(a_v) R_i`, `t_i' = a_t`.
//! A straight-line motion comes out unchanged, at the clip's ends and across dropped frames
//! too (a plain moving average would pull the ends inwards); a curved one is biased by about
//! `sigma^2 / 2` times its second derivative, never delayed.

use glam::{DQuat, DVec3};
use rayon::prelude::*;

use super::linalg::log_rotation;
use super::pnp::Pose;

/// The smoothed poses, one per input. `frames` (video frame indices, increasing) and
/// `poses` have the same length; `sigma <= 0` or `radius == 0` returns the input.
pub(crate) fn smooth_poses(
    frames: &[usize],
    poses: &[Pose],
    sigma: f64,
    radius: usize,
) -> Vec<Pose> {
    if sigma.is_nan() || sigma <= 0.0 || radius == 0 {
        return poses.to_vec();
    }
    (0..poses.len())
        .into_par_iter()
        .map(|i| smooth_one(frames, poses, i, sigma, radius))
        .collect()
}

fn smooth_one(frames: &[usize], poses: &[Pose], i: usize, sigma: f64, radius: usize) -> Pose {
    let centre = frames[i];
    let lo = frames[..i]
        .iter()
        .rposition(|&n| centre - n > radius)
        .map_or(0, |k| k + 1);
    let hi = frames[i..]
        .iter()
        .position(|&n| n - centre > radius)
        .map_or(frames.len(), |k| i + k);
    let inverse = poses[i].rotation.inverse();
    let mut rotation = LocalLinear::default();
    let mut translation = LocalLinear::default();
    for k in lo..hi {
        let dt = frames[k] as f64 - centre as f64;
        let w = (-dt * dt / (2.0 * sigma * sigma)).exp();
        rotation.add(dt, w, log_rotation(poses[k].rotation * inverse));
        translation.add(dt, w, poses[k].translation);
    }
    Pose {
        rotation: (DQuat::from_scaled_axis(rotation.at_zero()) * poses[i].rotation).normalize(),
        translation: translation.at_zero(),
    }
}

/// Weighted least squares of `y = a + b x`, accumulated; [`LocalLinear::at_zero`] is `a`.
#[derive(Default)]
struct LocalLinear {
    s0: f64,
    s1: f64,
    s2: f64,
    t0: DVec3,
    t1: DVec3,
}

impl LocalLinear {
    fn add(&mut self, x: f64, w: f64, y: DVec3) {
        self.s0 += w;
        self.s1 += w * x;
        self.s2 += w * x * x;
        self.t0 += w * y;
        self.t1 += (w * x) * y;
    }

    /// The fit's value at `x = 0`; the weighted mean when the `x` do not spread (one
    /// sample).
    fn at_zero(&self) -> DVec3 {
        let det = self.s0 * self.s2 - self.s1 * self.s1;
        if det > 1e-9 * self.s0 * self.s2 {
            (self.s2 * self.t0 - self.s1 * self.t1) / det
        } else {
            self.t0 / self.s0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pose::linalg::angle_between;

    /// A constant angular velocity about a fixed axis and a constant linear velocity: the
    /// fit is exact, so smoothing must return the poses unchanged, at the ends and across
    /// gaps as well.
    #[test]
    fn straight_motion_passes_unchanged() {
        let frames: Vec<usize> = (0..40).filter(|n| n % 7 != 3 && *n != 1).collect();
        let axis = DVec3::new(0.3, -0.8, 0.5).normalize();
        let poses: Vec<Pose> = frames
            .iter()
            .map(|&n| Pose {
                rotation: DQuat::from_scaled_axis(axis * 0.03 * n as f64)
                    * DQuat::from_rotation_x(0.4),
                translation: DVec3::new(0.01, -0.02, 0.005) * n as f64 + DVec3::Z,
            })
            .collect();
        let smoothed = smooth_poses(&frames, &poses, 1.5, 3);
        for (a, b) in poses.iter().zip(&smoothed) {
            assert!(angle_between(a.rotation, b.rotation) < 1e-12);
            assert!((a.translation - b.translation).length() < 1e-12);
        }
        assert_eq!(smooth_poses(&frames, &poses, 0.0, 3), poses);
    }
}
