//! The weighted landmarks the solver uses, checked once: which they are, their weights
//! scaled to mean 1, their canonical points; and the whole face rebuilt from them.

use glam::{DMat3, DVec2, DVec3, Vec3};

use super::config::{FrameLandmarks, MIN_WEIGHTED_POINTS};
use crate::error::{Error, Result};

/// The weighted landmarks.
pub(crate) struct Rig {
    /// Landmark indices with a positive weight.
    pub indices: Vec<usize>,
    /// Their weights scaled to mean 1 (so the bundle prior's balance does not depend on how
    /// the caller's weights are normalised).
    pub weights: Vec<f64>,
    /// Their canonical points.
    pub canonical: Vec<DVec3>,
}

impl Rig {
    /// The rig of `canonical` and `weights` (`[n_points]` each): errors on mismatched
    /// lengths, non-finite values, negative weights, fewer than [`MIN_WEIGHTED_POINTS`]
    /// weighted points, or weighted points on a plane.
    pub fn new(canonical: &[Vec3], weights: &[f32]) -> Result<Rig> {
        let fail = |p: String| Err(Error::Argument(format!("pose: {p}")));
        if canonical.len() != weights.len() {
            return fail(format!(
                "{} canonical points but {} weights",
                canonical.len(),
                weights.len()
            ));
        }
        if let Some(j) = canonical.iter().position(|p| !p.is_finite()) {
            return fail(format!(
                "canonical point {j} is not finite: {}",
                canonical[j]
            ));
        }
        if let Some(j) = weights.iter().position(|w| !(*w >= 0.0 && w.is_finite())) {
            return fail(format!(
                "weight {j} is {}, not a finite number >= 0",
                weights[j]
            ));
        }
        let indices: Vec<usize> = (0..weights.len()).filter(|&j| weights[j] > 0.0).collect();
        if indices.len() < MIN_WEIGHTED_POINTS {
            return fail(format!(
                "{} weighted landmarks, a pose needs {MIN_WEIGHTED_POINTS}",
                indices.len()
            ));
        }
        let total: f64 = indices.iter().map(|&j| f64::from(weights[j])).sum();
        let scale = indices.len() as f64 / total;
        let rig = Rig {
            weights: indices
                .iter()
                .map(|&j| f64::from(weights[j]) * scale)
                .collect(),
            canonical: indices.iter().map(|&j| canonical[j].as_dvec3()).collect(),
            indices,
        };
        let (_, cov) = rig.spread(&rig.canonical);
        let trace = cov.x_axis.x + cov.y_axis.y + cov.z_axis.z;
        // The determinant against its value for the same spread in every direction.
        let det = cov.determinant();
        if det.is_nan() || det <= 1e-6 * (trace / 3.0).powi(3) {
            return fail("the weighted canonical points lie on a plane or a line".into());
        }
        Ok(rig)
    }

    /// Weighted mean and covariance `sum w (p - mean)(p - mean)^T` of `points`.
    fn spread(&self, points: &[DVec3]) -> (DVec3, DMat3) {
        let total: f64 = self.weights.iter().sum();
        let pairs = || points.iter().zip(&self.weights);
        let mean = pairs().fold(DVec3::ZERO, |a, (p, w)| a + *w * *p) / total;
        let cov = pairs().fold(DMat3::ZERO, |a, (p, w)| {
            a + outer(*p - mean, *p - mean) * *w
        });
        (mean, cov)
    }

    /// The frame's weighted landmarks in pixels.
    pub fn pixels(&self, frame: &FrameLandmarks) -> Vec<DVec2> {
        self.indices
            .iter()
            .map(|&j| DVec2::new(f64::from(frame.points[j][0]), f64::from(frame.points[j][1])))
            .collect()
    }

    /// All points of the face. With `refined` (the weighted points after the bundle step),
    /// the weighted points are those and the others are carried by the affine map `A` that
    /// best takes the weighted canonical points onto them (weighted least squares:
    /// `A = M C^-1`, `M = sum w r' c'^T`, `C = sum w c' c'^T` on centred points), which
    /// follows a stretch of the whole face but not any one point's offset. Without, the
    /// canonical face.
    pub fn full_face(&self, canonical: &[Vec3], refined: Option<&[DVec3]>) -> Vec<Vec3> {
        let Some(refined) = refined else {
            return canonical.to_vec();
        };
        let (c_mean, c_cov) = self.spread(&self.canonical);
        let r_mean = refined
            .iter()
            .zip(&self.weights)
            .fold(DVec3::ZERO, |a, (p, w)| a + *w * *p)
            / self.weights.iter().sum::<f64>();
        let m = refined
            .iter()
            .zip(&self.canonical)
            .zip(&self.weights)
            .fold(DMat3::ZERO, |a, ((r, c), w)| {
                a + outer(*r - r_mean, *c - c_mean) * *w
            });
        // `c_cov` is invertible: `new` refused weighted points on a plane.
        let affine = m * c_cov.inverse();
        let mut face: Vec<Vec3> = canonical
            .iter()
            .map(|p| (affine * (p.as_dvec3() - c_mean) + r_mean).as_vec3())
            .collect();
        for (slot, &j) in self.indices.iter().enumerate() {
            face[j] = refined[slot].as_vec3();
        }
        face
    }
}

/// `a b^T`.
fn outer(a: DVec3, b: DVec3) -> DMat3 {
    DMat3::from_cols(a * b.x, a * b.y, a * b.z)
}
