//! The head-pose stage of `nldf prepare`: the camera track solved from the face helper's
//! landmarks and feature tracks ([`crate::pose`]) at a given size.

use nldf_core::camera::Intrinsics;

use crate::error::Result;
use crate::face::{FaceEnv, FaceOutput};
use crate::pose::{CameraTrack, PoseConfig, solve_track};

/// The head-pose stage: the intrinsics of frames `size` pixels across with focal length
/// `focal` and the track of the `kept` frames, solved by [`solve_track`] with `cfg` from
/// the face helper's landmarks and tracks in `faces`.
pub(crate) fn solve_poses(
    env: &FaceEnv,
    faces: &FaceOutput,
    kept: &[usize],
    size: u32,
    focal: f32,
    cfg: &PoseConfig,
) -> Result<(Intrinsics, CameraTrack)> {
    let k = square_intrinsics(size, focal);
    let canonical = env.canonical()?;
    let track = solve_track(
        &faces.landmark_frames(kept),
        &faces.tracks,
        &canonical.vertices,
        &canonical.rigid_weights,
        &k,
        cfg,
    )?;
    Ok((k, track))
}

/// The intrinsics of square frames `size` pixels across, centred, focal length `focal`.
pub(crate) fn square_intrinsics(size: u32, focal: f32) -> Intrinsics {
    Intrinsics {
        focal,
        cx: size as f32 / 2.0,
        cy: size as f32 / 2.0,
        width: size,
        height: size,
    }
}
