//! Head pose without a 3DMM: mediapipe's 468 face landmarks of every frame turned into
//! AD-NeRF's camera track (the head fixed at the origin, the camera moving).
//!
//! [`solve_track`] runs five steps:
//! 1. PnP of each frame's weighted landmarks against the canonical face (`pnp`): a
//!    weak-perspective closed form, then Levenberg-Marquardt on the full perspective
//!    reprojection error, in f64, every frame on its own (in parallel);
//! 2. when the head turns enough, a bundle step (`bundle`) that refines the face's weighted
//!    points together with the poses of evenly spaced key frames, with a prior towards the
//!    canonical face and the canonical's centroid, scale and orientation kept; then PnP again
//!    against the refined face;
//! 3. when feature tracks are given and enough of them hold, the poses from the tracks
//!    (`tracks`): a bundle of the tracks' points and key poses started from step 2, set in
//!    step 2's world, then PnP of every frame against the tracks' points. Landmarks are
//!    a face model fitted to the image and lean with it; tracks are points of the head;
//! 4. temporal smoothing without lag (`smooth`);
//! 5. the head pose `p = R x + t` (OpenCV camera axes) turned into a camera-to-world matrix
//!    with OpenGL axes, nldf-core's convention: `c2w = [R^T D | -R^T t]`,
//!    `D = diag(1, -1, -1)`, so that `Camera { intrinsics, c2w }.project(x)` lands on the
//!    landmark of face point `x`.

mod bundle;
mod config;
pub(crate) mod linalg;
mod pnp;
mod rig;
mod smooth;
#[cfg(test)]
mod tests;
mod track_bundle;
mod tracks;

pub use config::{CameraTrack, FrameLandmarks, MIN_WEIGHTED_POINTS, PoseConfig, TrackSummary};
pub use tracks::{MAX_DEPARTURE_DEG, MIN_FRAME_POINTS, MIN_KEY_VIEWS, TrackPoint};

use glam::{DMat3, DMat4, DVec2, DVec3, DVec4, Mat4, Vec3};
use nldf_core::camera::Intrinsics;
use rayon::prelude::*;

use crate::error::{Error, Result};
use config::key_frames;
use pnp::{Pinhole, Pose};
use rig::Rig;

/// Solves the camera track of a clip from its face landmarks (see the module docs).
///
/// `canonical` and `weights` are `[n_points]` (mediapipe: the canonical face model in metres
/// and the procrustes landmark weights; zero for landmarks that move with the mouth or
/// eyes); every frame's `points` is `[n_points]`; frames increase in `frame`. `k.focal` is
/// used as given: a wrong one scales the camera's distance with it and bends the rotations
/// a little (a too-short focal more than a too-long one). Errors on empty or mismatched
/// input, non-finite values, fewer than [`MIN_WEIGHTED_POINTS`] weighted points, a flat
/// weighted face, and frames whose landmarks no pose fits.
///
/// `tracks` are feature tracks on the head (any order; points of frames not in `frames`
/// and non-finite pixels are ignored); with none, or too few that hold, the poses are the
/// landmarks' alone.
pub fn solve_track(
    frames: &[FrameLandmarks],
    tracks: &[TrackPoint],
    canonical: &[Vec3],
    weights: &[f32],
    k: &Intrinsics,
    cfg: &PoseConfig,
) -> Result<CameraTrack> {
    cfg.validate()?;
    let cam = pinhole(k)?;
    let rig = Rig::new(canonical, weights)?;
    check_frames(frames, canonical.len())?;
    let first = solve_all(frames, &rig, &rig.canonical, &cam, cfg.pnp_iterations)?;
    let spread = rotation_spread_deg(&first);
    let bundled = cfg.bundle_iterations > 0
        && spread >= f64::from(cfg.bundle_min_spread_deg)
        && frames.len() >= 3;
    let (face, poses) = if bundled {
        let face = refine_face(frames, &rig, &cam, &first, cfg);
        let poses = solve_all(frames, &rig, &face, &cam, cfg.pnp_iterations)?;
        (face, poses)
    } else {
        (rig.canonical.clone(), first)
    };
    let indices: Vec<usize> = frames.iter().map(|f| f.frame).collect();
    let tracked = tracks::refine_with_tracks(&indices, &poses, tracks, &cam, cfg);
    let poses = tracked.as_ref().map_or(poses, |t| t.poses.clone());
    let poses = smooth::smooth_poses(
        &indices,
        &poses,
        f64::from(cfg.smooth_sigma_frames),
        cfg.smooth_radius_frames,
    );
    let reprojection_px: Vec<f32> = frames
        .par_iter()
        .zip(&poses)
        .map(|(f, pose)| pnp::rms_px(pose, &face, &rig.pixels(f), &rig.weights, &cam) as f32)
        .collect();
    let track = CameraTrack {
        c2w: poses.iter().map(camera_to_world).collect(),
        face: rig.full_face(canonical, bundled.then_some(&face[..])),
        bundled,
        rotation_spread_deg: spread as f32,
        reprojection_px,
        tracks: tracked.map_or_else(TrackSummary::default, |t| t.summary),
    };
    let finite = track.c2w.iter().all(|m| m.is_finite())
        && track.face.iter().all(|p| p.is_finite())
        && track.reprojection_px.iter().all(|e| e.is_finite());
    if !finite {
        return Err(Error::Argument(
            "pose: the solved track is not finite (landmarks far outside the image?)".into(),
        ));
    }
    Ok(track)
}

fn pinhole(k: &Intrinsics) -> Result<Pinhole> {
    if !(k.focal > 0.0 && k.focal.is_finite() && k.cx.is_finite() && k.cy.is_finite()) {
        return Err(Error::Argument(format!(
            "pose: intrinsics need a finite focal > 0 and a finite principal point, got focal {} cx {} cy {}",
            k.focal, k.cx, k.cy
        )));
    }
    Ok(Pinhole {
        focal: f64::from(k.focal),
        cx: f64::from(k.cx),
        cy: f64::from(k.cy),
    })
}

fn check_frames(frames: &[FrameLandmarks], n_points: usize) -> Result<()> {
    if frames.is_empty() {
        return Err(Error::Argument("pose: no frames with landmarks".into()));
    }
    for (i, f) in frames.iter().enumerate() {
        let problem = if f.points.len() != n_points {
            Some(format!(
                "{} landmarks, the canonical face has {n_points}",
                f.points.len()
            ))
        } else if let Some(j) = f
            .points
            .iter()
            .position(|p| !(p[0].is_finite() && p[1].is_finite()))
        {
            Some(format!("landmark {j} is not finite: {:?}", f.points[j]))
        } else if i > 0 && f.frame <= frames[i - 1].frame {
            Some(format!(
                "comes after frame {}: frames must increase",
                frames[i - 1].frame
            ))
        } else {
            None
        };
        if let Some(p) = problem {
            return Err(Error::Argument(format!("pose: frame {}: {p}", f.frame)));
        }
    }
    Ok(())
}

/// PnP of every frame on its own against `face` (the weighted points).
fn solve_all(
    frames: &[FrameLandmarks],
    rig: &Rig,
    face: &[DVec3],
    cam: &Pinhole,
    iterations: usize,
) -> Result<Vec<Pose>> {
    frames
        .par_iter()
        .map(|f| {
            pnp::solve_frame(face, &rig.pixels(f), &rig.weights, cam, iterations).ok_or_else(|| {
                Error::Argument(format!(
                    "pose: frame {}: no head pose fits the landmarks (they collapse onto a point or a line, or put the face behind the camera)",
                    f.frame
                ))
            })
        })
        .collect()
}

/// RMS angle in degrees between the poses' rotations and their mean.
fn rotation_spread_deg(poses: &[Pose]) -> f64 {
    let rotations: Vec<_> = poses.iter().map(|p| p.rotation).collect();
    let mean = linalg::mean_rotation(&rotations);
    let sum: f64 = rotations
        .iter()
        .map(|q| linalg::angle_between(mean, *q).powi(2))
        .sum();
    (sum / poses.len() as f64).sqrt().to_degrees()
}

/// The bundle step on evenly spaced key frames; returns the refined weighted points.
fn refine_face(
    frames: &[FrameLandmarks],
    rig: &Rig,
    cam: &Pinhole,
    poses: &[Pose],
    cfg: &PoseConfig,
) -> Vec<DVec3> {
    let keys = key_frames(frames.len(), cfg.bundle_frames);
    let pixels: Vec<Vec<DVec2>> = keys.iter().map(|&i| rig.pixels(&frames[i])).collect();
    let key_poses: Vec<Pose> = keys.iter().map(|&i| poses[i]).collect();
    let sigma_m = f64::from(cfg.bundle_prior_mm) * 1e-3;
    let problem = bundle::Bundle {
        canonical: &rig.canonical,
        weights: &rig.weights,
        pixels: &pixels,
        cam: *cam,
        prior: 1.0 / (sigma_m * sigma_m),
    };
    problem
        .run(rig.canonical.clone(), key_poses, cfg.bundle_iterations)
        .0
}

/// `c2w = [R^T D | -R^T t]` with `D = diag(1, -1, -1)`: OpenCV camera axes to OpenGL ones.
fn camera_to_world(pose: &Pose) -> Mat4 {
    let r = DMat3::from_quat(pose.rotation);
    let position = -(r.transpose() * pose.translation);
    DMat4::from_cols(
        r.row(0).extend(0.0),
        (-r.row(1)).extend(0.0),
        (-r.row(2)).extend(0.0),
        DVec4::new(position.x, position.y, position.z, 1.0),
    )
    .as_mat4()
}
