//! The similarity that maps one camera track onto another, and the errors left after it.
//!
//! A camera track recovered from a monocular video is the true one up to a constant
//! similarity that no method can observe: the scale of the world, the orientation of the
//! head's axes, and the point of the head called its origin. [`align_tracks`] finds that
//! similarity `x_true ≈ s Q x_est + t` (scale `s > 0`, rotation `Q`, translation `t`) and
//! scores what remains, frame by frame:
//!
//! - the rotation error, the angle of `R_true^T (Q R_est)` in degrees;
//! - the camera-centre error `|s Q c_est + t - c_true| / |c_true|`, a fraction of the true
//!   camera's distance from the head (the origin of the true track).
//!
//! `Q` uses both what the cameras say about it: the centres (Umeyama's cross-covariance of
//! the centred camera centres, each track divided by its RMS spread) and the orientations
//! (the sum of `R_true R_est^T`), with equal weight; the two summed matrices `M` give the
//! rotation that maximises `tr(Q^T M)` by Horn's quaternion method. Given `Q`, `s` and `t`
//! are Umeyama's least-squares values for the centres. Everything is computed in f64.

use glam::{DMat3, DMat4, DQuat, DVec3};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::pose::linalg::top_eigenvector4;

/// A camera's pose in a track: its camera-to-world rotation (OpenGL axes, as AD-NeRF's
/// `transform_matrix`) and its centre.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraPose {
    pub rotation: DMat3,
    pub centre: DVec3,
}

impl CameraPose {
    /// The pose of a 4 x 4 camera-to-world matrix given as rows (a transforms file's
    /// `transform_matrix`).
    pub fn from_rows(rows: &[[f32; 4]; 4]) -> CameraPose {
        let m = DMat4::from_cols_array_2d(&rows.map(|r| r.map(f64::from))).transpose();
        CameraPose {
            rotation: DMat3::from_mat4(m),
            centre: m.w_axis.truncate(),
        }
    }

    /// The 4 x 4 camera-to-world matrix as rows (a transforms file's `transform_matrix`).
    pub fn to_rows(&self) -> [[f32; 4]; 4] {
        let m = DMat4::from_cols(
            self.rotation.x_axis.extend(0.0),
            self.rotation.y_axis.extend(0.0),
            self.rotation.z_axis.extend(0.0),
            self.centre.extend(1.0),
        );
        m.transpose()
            .to_cols_array_2d()
            .map(|r| r.map(|v| v as f32))
    }
}

/// A similarity `x -> s Q x + t` of the world, applied to camera tracks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Similarity {
    /// `s`, positive.
    pub scale: f64,
    /// `Q`, a rotation.
    pub rotation: DMat3,
    /// `t`.
    pub translation: DVec3,
}

impl Similarity {
    /// The pose of a camera moved by the similarity: rotation `Q R`, centre `s Q c + t`.
    pub fn apply(&self, pose: &CameraPose) -> CameraPose {
        CameraPose {
            rotation: self.rotation * pose.rotation,
            centre: self.apply_point(pose.centre),
        }
    }

    /// The image of a point, `s Q x + t`.
    pub fn apply_point(&self, x: DVec3) -> DVec3 {
        self.scale * (self.rotation * x) + self.translation
    }

    /// The inverse similarity: `x -> (1/s) Q^T (x - t)`.
    pub fn inverse(&self) -> Similarity {
        let q_inv = self.rotation.transpose();
        Similarity {
            scale: 1.0 / self.scale,
            rotation: q_inv,
            translation: -(q_inv * self.translation) / self.scale,
        }
    }
}

/// The similarity that maps an estimated track onto the true one, and the errors left.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackAlignment {
    /// Maps the estimate onto the truth.
    pub similarity: Similarity,
    /// Per frame: the angle of `R_true^T (Q R_est)`, degrees.
    pub rotation_deg: Vec<f64>,
    /// Per frame: `|s Q c_est + t - c_true| / |c_true|`.
    pub position: Vec<f64>,
    /// The means and the worsts, with the similarity's parameters.
    pub errors: TrackErrors,
}

/// The summary of a [`TrackAlignment`]'s per-frame errors.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TrackErrors {
    /// Mean rotation error, degrees.
    pub rotation_mean_deg: f64,
    /// Largest rotation error, degrees.
    pub rotation_worst_deg: f64,
    /// Mean camera-centre error, a fraction of the true camera's distance to the head.
    pub position_mean: f64,
    /// Largest camera-centre error, the same fraction.
    pub position_worst: f64,
    /// The similarity's scale `s`.
    pub scale: f64,
    /// The angle of its rotation `Q`, degrees.
    pub rotation_deg: f64,
    /// Its translation `t`.
    pub translation: [f64; 3],
}

/// Aligns `estimate` onto `truth` (the same frames, in the same order) by the similarity
/// described in the module docs, and returns it with the errors left after it. Errors: the
/// tracks differ in length or are empty, a value is not finite, or a true camera sits at
/// the head (distance 0).
pub fn align_tracks(truth: &[CameraPose], estimate: &[CameraPose]) -> Result<TrackAlignment> {
    check_tracks(truth, estimate)?;
    let similarity = fit_similarity(truth, estimate);
    let (rotation_deg, position): (Vec<f64>, Vec<f64>) = truth
        .iter()
        .zip(estimate)
        .map(|(t, e)| {
            let moved = similarity.apply(e);
            (
                rotation_angle_deg(t.rotation.transpose() * moved.rotation),
                (moved.centre - t.centre).length() / t.centre.length(),
            )
        })
        .unzip();
    let n = truth.len() as f64;
    let errors = TrackErrors {
        rotation_mean_deg: rotation_deg.iter().sum::<f64>() / n,
        rotation_worst_deg: rotation_deg.iter().copied().fold(0.0, f64::max),
        position_mean: position.iter().sum::<f64>() / n,
        position_worst: position.iter().copied().fold(0.0, f64::max),
        scale: similarity.scale,
        rotation_deg: rotation_angle_deg(similarity.rotation),
        translation: similarity.translation.to_array(),
    };
    Ok(TrackAlignment {
        similarity,
        rotation_deg,
        position,
        errors,
    })
}

/// The angle of a rotation matrix in degrees, `atan2(|v|, tr R - 1)` with `v` the vector of
/// `R - R^T` (`|v| = 2 sin θ`, `tr R - 1 = 2 cos θ`): accurate for small and large angles.
pub fn rotation_angle_deg(r: DMat3) -> f64 {
    let v = DVec3::new(
        r.y_axis.z - r.z_axis.y,
        r.z_axis.x - r.x_axis.z,
        r.x_axis.y - r.y_axis.x,
    );
    let trace = r.x_axis.x + r.y_axis.y + r.z_axis.z;
    v.length().atan2(trace - 1.0).to_degrees()
}

/// Both tracks non-empty, of one length, finite, and no true camera at the origin.
fn check_tracks(truth: &[CameraPose], estimate: &[CameraPose]) -> Result<()> {
    if truth.len() != estimate.len() {
        return Err(Error::Argument(format!(
            "camera tracks of {} true and {} estimated frames cannot be aligned",
            truth.len(),
            estimate.len()
        )));
    }
    if truth.is_empty() {
        return Err(Error::Argument("no frames to align".into()));
    }
    let finite = |p: &CameraPose| p.rotation.is_finite() && p.centre.is_finite();
    for (k, (t, e)) in truth.iter().zip(estimate).enumerate() {
        if !finite(t) || !finite(e) {
            return Err(Error::Argument(format!(
                "frame {k} of the camera tracks holds a value that is not finite"
            )));
        }
        if t.centre.length() <= f64::EPSILON {
            return Err(Error::Argument(format!(
                "frame {k}: the true camera sits at the head (distance 0)"
            )));
        }
    }
    Ok(())
}

/// The similarity of the module docs that maps `estimate` onto `truth` (checked tracks).
fn fit_similarity(truth: &[CameraPose], estimate: &[CameraPose]) -> Similarity {
    let n = truth.len() as f64;
    let mean = |track: &[CameraPose]| track.iter().map(|p| p.centre).sum::<DVec3>() / n;
    let (mean_t, mean_e) = (mean(truth), mean(estimate));
    let spread = |track: &[CameraPose], m: DVec3| {
        (track
            .iter()
            .map(|p| (p.centre - m).length_squared())
            .sum::<f64>()
            / n)
            .sqrt()
    };
    let (rms_t, rms_e) = (spread(truth, mean_t), spread(estimate, mean_e));
    // A track whose centres do not spread says nothing about Q through them.
    let spreads = |rms: f64, m: DVec3| rms > 1e-12 * m.length().max(1.0);
    let use_centres = spreads(rms_t, mean_t) && spreads(rms_e, mean_e);
    let mut m = DMat3::ZERO;
    for (t, e) in truth.iter().zip(estimate) {
        m += t.rotation * e.rotation.transpose();
        if use_centres {
            m += outer((t.centre - mean_t) / rms_t, (e.centre - mean_e) / rms_e);
        }
    }
    let q = best_rotation(&m);
    // Umeyama's scale given Q; where it is not positive, the ratio of the mean distances
    // from the head.
    let (num, den) = truth
        .iter()
        .zip(estimate)
        .fold((0.0, 0.0), |(num, den), (t, e)| {
            let (a, b) = (t.centre - mean_t, q * (e.centre - mean_e));
            (num + a.dot(b), den + b.length_squared())
        });
    let scale = if use_centres && num > 0.0 {
        num / den
    } else {
        let dist = |track: &[CameraPose]| track.iter().map(|p| p.centre.length()).sum::<f64>();
        let (d_t, d_e) = (dist(truth), dist(estimate));
        if d_e > f64::EPSILON { d_t / d_e } else { 1.0 }
    };
    Similarity {
        scale,
        rotation: q,
        translation: mean_t - scale * (q * mean_e),
    }
}

/// `a b^T`.
fn outer(a: DVec3, b: DVec3) -> DMat3 {
    DMat3::from_cols(a * b.x, a * b.y, a * b.z)
}

/// The rotation `Q` that maximises `tr(Q^T M)`, by Horn's quaternion method: the unit
/// eigenvector of the largest eigenvalue of the symmetric 4 x 4 matrix built from `M`
/// (Horn 1987, "Closed-form solution of absolute orientation using unit quaternions",
/// section 4), with `S = M^T` the sum of `est truth^T` products.
fn best_rotation(m: &DMat3) -> DMat3 {
    let s = |i: usize, j: usize| m.col(i)[j];
    let (sxx, sxy, sxz) = (s(0, 0), s(0, 1), s(0, 2));
    let (syx, syy, syz) = (s(1, 0), s(1, 1), s(1, 2));
    let (szx, szy, szz) = (s(2, 0), s(2, 1), s(2, 2));
    let n = [
        [sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
        [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
        [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
        [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz],
    ];
    let q = top_eigenvector4(n);
    DMat3::from_quat(DQuat::from_xyzw(q[1], q[2], q[3], q[0]).normalize())
}

#[cfg(test)]
mod tests {
    use std::f64::consts::TAU;

    use glam::EulerRot;

    use super::*;

    /// A true track of `n` frames as `nldf synth` makes one: the world camera 1 unit up +z
    /// looking at the head, the head turning (yaw up to 20°, pitch 12°, roll 8°) and
    /// shifting by up to 0.015, so the camera in head space is the inverse head pose.
    fn truth_track(n: usize) -> Vec<CameraPose> {
        (0..n)
            .map(|i| {
                let t = TAU * i as f64 / n as f64;
                let head = DMat3::from_euler(
                    EulerRot::YXZ,
                    20f64.to_radians() * t.sin(),
                    12f64.to_radians() * (2.0 * t + 0.5).sin(),
                    8f64.to_radians() * (3.0 * t + 1.0).cos(),
                );
                let shift = 0.015 * DVec3::new(t.cos(), (2.0 * t).sin(), (t + 2.0).sin());
                let to_head = head.transpose();
                CameraPose {
                    rotation: to_head,
                    centre: to_head * (DVec3::Z - shift),
                }
            })
            .collect()
    }

    /// The similarity the tests hide the truth behind.
    fn hidden() -> Similarity {
        Similarity {
            scale: 0.37,
            rotation: DMat3::from_axis_angle(DVec3::new(1.0, -2.0, 0.5).normalize(), 2.1),
            translation: DVec3::new(0.2, -0.5, 3.0),
        }
    }

    /// The truth as a method that cannot see `hidden()` would estimate it.
    fn estimate_of(truth: &[CameraPose]) -> Vec<CameraPose> {
        let inv = hidden().inverse();
        truth.iter().map(|p| inv.apply(p)).collect()
    }

    #[test]
    fn a_track_moved_by_a_similarity_aligns_with_zero_error() {
        let truth = truth_track(60);
        let a = align_tracks(&truth, &estimate_of(&truth)).unwrap();
        let e = a.errors;
        assert!(e.rotation_worst_deg < 1e-9, "{e:?}");
        assert!(e.position_worst < 1e-12, "{e:?}");
        let found = a.similarity;
        assert!((found.scale - 0.37).abs() < 1e-12, "{found:?}");
        let off = rotation_angle_deg(found.rotation.transpose() * hidden().rotation);
        assert!(off < 1e-9, "Q off by {off} degrees");
        assert!((found.translation - hidden().translation).length() < 1e-12);
        // One frame, and a camera that never moves, align exactly too.
        for track in [truth[..1].to_vec(), vec![truth[3]; 10]] {
            let e = align_tracks(&track, &estimate_of(&track)).unwrap().errors;
            assert!(
                e.rotation_worst_deg < 1e-9 && e.position_worst < 1e-12,
                "{e:?}"
            );
        }
    }

    #[test]
    fn a_planted_3_degree_rotation_shows_up_as_the_worst() {
        let truth = truth_track(50);
        let mut estimate = estimate_of(&truth);
        estimate[17].rotation *= DMat3::from_rotation_x(3f64.to_radians());
        let a = align_tracks(&truth, &estimate).unwrap();
        let worst = (0..50)
            .max_by(|&i, &j| a.rotation_deg[i].total_cmp(&a.rotation_deg[j]))
            .unwrap();
        assert_eq!(worst, 17);
        // The fit leans towards the planted frame by at most 3° / 50, moving every other
        // frame's error by as much.
        let lean = 3.0 / 50.0;
        let e = a.errors;
        assert!((3.0 - lean..=3.0).contains(&e.rotation_worst_deg), "{e:?}");
        assert!(
            a.rotation_deg
                .iter()
                .enumerate()
                .all(|(k, &d)| k == 17 || d <= lean)
        );
        assert!(
            (3.0 / 50.0..=2.0 * lean).contains(&e.rotation_mean_deg),
            "{e:?}"
        );
        assert!(a.errors.position_worst < 1e-3, "{:?}", a.errors);
    }

    #[test]
    fn a_planted_camera_shift_shows_up_as_a_fraction_of_the_distance() {
        let truth = truth_track(50);
        let mut estimate = estimate_of(&truth);
        // 2 % of the true distance (about 1), in the estimate's scale (1 / 0.37).
        estimate[8].centre += DVec3::new(0.0, 0.02 / 0.37, 0.0);
        let a = align_tracks(&truth, &estimate).unwrap();
        let distance = truth[8].centre.length();
        assert!(
            (a.position[8] - 0.02 / distance).abs() < 1e-3,
            "{:?}",
            a.position[8]
        );
        assert_eq!(a.errors.position_worst, a.position[8]);
        assert!(a.errors.rotation_worst_deg < 0.05, "{:?}", a.errors);
    }

    #[test]
    fn the_angle_of_a_rotation_is_accurate_small_and_large() {
        for deg in [0.0f64, 1e-7, 0.01, 3.0, 90.0, 179.9, 180.0] {
            let r =
                DMat3::from_axis_angle(DVec3::new(0.3, 0.9, -0.2).normalize(), deg.to_radians());
            let got = rotation_angle_deg(r);
            assert!((got - deg).abs() <= 1e-9 * deg.max(1.0), "{deg}: {got}");
        }
    }

    #[test]
    fn a_pose_round_trips_through_transform_matrix_rows() {
        let pose = truth_track(7)[3];
        let rows = pose.to_rows();
        assert_eq!(rows[3], [0.0, 0.0, 0.0, 1.0]);
        assert_eq!(rows[1][3], pose.centre.y as f32);
        let back = CameraPose::from_rows(&rows);
        assert!((back.centre - pose.centre).length() < 1e-7);
        assert!(rotation_angle_deg(back.rotation.transpose() * pose.rotation) < 1e-5);
    }

    #[test]
    fn tracks_that_cannot_be_aligned_are_refused() {
        let truth = truth_track(5);
        let err = |t: &[CameraPose], e: &[CameraPose]| align_tracks(t, e).unwrap_err().to_string();
        assert!(err(&truth, &truth[..4]).contains("5 true and 4 estimated"));
        assert!(err(&[], &[]).contains("no frames"));
        let mut bad = truth.clone();
        bad[2].centre.x = f64::NAN;
        assert!(err(&truth, &bad).contains("frame 2"));
        let mut at_head = truth.clone();
        at_head[1].centre = DVec3::ZERO;
        assert!(err(&at_head, &truth).contains("frame 1"));
    }
}
