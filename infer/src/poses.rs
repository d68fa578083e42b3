//! Camera poses per video frame: from a transforms json (AD-NeRF's `transforms_*.json`,
//! every `transform_matrix` checked to be a rigid camera-to-world transform), or a smooth
//! default track that sways the camera a little around the head, starting from the model's
//! default pose.

use std::path::Path;

use glam::Mat4;
use nldf_core::camera::{rigid_problem, turn_about};
use nldf_core::dataset::{RIGID_TOL, TransformsFile};
use nldf_model::contract::ModelInfo;

use crate::error::{Error, Result};

/// Reads the camera-to-world matrices of a transforms json, in file order.
pub fn poses_from_transforms(path: &Path) -> Result<Vec<Mat4>> {
    let file = TransformsFile::load(path).map_err(|e| {
        // JSON has no NaN or Infinity; Python's json module writes them anyway.
        let text = std::fs::read_to_string(path).unwrap_or_default();
        if ["NaN", "Infinity"].iter().any(|t| text.contains(t)) {
            Error::Core(nldf_core::Error::invalid(
                path,
                "holds NaN or Infinity: every transform_matrix entry must be a finite number",
            ))
        } else {
            Error::Core(e)
        }
    })?;
    if file.frames.is_empty() {
        return Err(Error::Core(nldf_core::Error::invalid(
            path,
            "holds no frames",
        )));
    }
    file.frames
        .iter()
        .enumerate()
        .map(|(frame, f)| {
            let c2w = Mat4::from_cols_array_2d(&f.transform_matrix).transpose();
            match rigid_problem(&c2w, RIGID_TOL) {
                Some(problem) => Err(Error::Pose {
                    path: path.to_path_buf(),
                    frame,
                    problem,
                }),
                None => Ok(c2w),
            }
        })
        .collect()
}

/// The pose of video frame `f` from a list of `poses`: played forwards, then backwards, and
/// so on, so that a short list never jumps.
pub fn pose_at(poses: &[Mat4], f: usize) -> Mat4 {
    match poses.len() {
        0 => Mat4::IDENTITY,
        1 => poses[0],
        n => {
            let period = 2 * (n - 1);
            let k = f % period;
            poses[if k < n { k } else { period - k }]
        }
    }
}

/// The default track: the model's default pose turned about the head's centre by a slow
/// sway (yaw within 4 degrees, pitch within 2, periods of about 5 to 9 seconds), one pose per
/// video frame at the model's fps. Deterministic.
pub fn default_track(info: &ModelInfo, n_frames: usize) -> Vec<Mat4> {
    (0..n_frames).map(|f| default_pose(info, f)).collect()
}

/// Frame `f` of the [`default_track`], for tracks of unknown length (a stream).
pub fn default_pose(info: &ModelInfo, f: usize) -> Mat4 {
    let spec = &info.spec;
    let start = Mat4::from_cols_array_2d(&spec.default_pose).transpose();
    let centre = 0.5 * (spec.bounds.lo + spec.bounds.hi);
    let t = f as f32 / spec.fps;
    let tau = std::f32::consts::TAU;
    let yaw = 4f32.to_radians() * (0.7 * (tau * 0.11 * t).sin() + 0.3 * (tau * 0.19 * t).sin());
    let pitch = 2f32.to_radians() * (tau * 0.13 * t + 0.5).sin() - 2f32.to_radians() * 0.5f32.sin();
    turn_about(centre, yaw, pitch) * start
}
