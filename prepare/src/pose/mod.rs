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
mod linalg;
mod pnp;
mod rig;
mod smooth;
#[cfg(test)]
mod tests;
mod track_bundle;
mod tracks;

pub use tracks::{MAX_DEPARTURE_DEG, MIN_FRAME_POINTS, MIN_KEY_VIEWS, TrackPoint};

use glam::{DMat3, DMat4, DVec2, DVec3, DVec4, Mat4, Vec3};
use nldf_core::camera::Intrinsics;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use pnp::{Pinhole, Pose};
use rig::Rig;

/// Fewest weighted landmarks a pose is solved from.
pub const MIN_WEIGHTED_POINTS: usize = 6;

/// Most key frames the bundle step accepts: its dense system has `6 n` unknowns.
const MAX_BUNDLE_FRAMES: usize = 500;

/// How the camera track is solved; the defaults suit mediapipe landmarks of a 25 fps clip.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PoseConfig {
    /// Levenberg-Marquardt iterations of each frame's PnP (default 20).
    pub pnp_iterations: usize,
    /// The bundle step runs only when the head turns at least this much: the RMS angle in
    /// degrees between the frames' PnP rotations and their mean (default 5). With less
    /// motion the face's depth is barely observable and the canonical face stays.
    pub bundle_min_spread_deg: f32,
    /// Key frames, evenly spaced over the clip, solved together with the face (default 100).
    pub bundle_frames: usize,
    /// Levenberg-Marquardt iterations of the bundle step; 0 turns it off (default 30).
    pub bundle_iterations: usize,
    /// The prior's standard deviation in mm: a face point this far from the canonical one
    /// costs as much as one pixel of reprojection error in one key frame (default 10).
    pub bundle_prior_mm: f32,
    /// Gaussian sigma of the temporal smoothing, in video frames; 0 turns it off
    /// (default 1.5).
    pub smooth_sigma_frames: f32,
    /// Half-width of the smoothing window, in video frames (default 3).
    pub smooth_radius_frames: usize,
    /// Levenberg-Marquardt iterations of each round of the track bundle; 0 turns the
    /// tracks off (default 20).
    pub track_iterations: usize,
    /// Key frames of the track bundle, evenly spaced over the clip (default 100).
    pub track_key_frames: usize,
    /// Fewest tracks that must survive the bundle's rounds for their poses to be used
    /// (default 20).
    pub track_min_points: usize,
    /// Huber's `delta` of the track residuals, pixels (default 1).
    pub track_huber_px: f32,
    /// A track is dropped when its RMS residual exceeds this many times the median
    /// track's (default 2) ...
    pub track_reject_factor: f32,
    /// ... and this many pixels (default 0.2).
    pub track_reject_floor_px: f32,
}

impl Default for PoseConfig {
    fn default() -> Self {
        PoseConfig {
            pnp_iterations: 20,
            bundle_min_spread_deg: 5.0,
            bundle_frames: 100,
            bundle_iterations: 30,
            bundle_prior_mm: 10.0,
            smooth_sigma_frames: 1.5,
            smooth_radius_frames: 3,
            track_iterations: 20,
            track_key_frames: 100,
            track_min_points: 20,
            track_huber_px: 1.0,
            track_reject_factor: 2.0,
            track_reject_floor_px: 0.2,
        }
    }
}

impl PoseConfig {
    /// Why this configuration cannot be used, as an error naming the field.
    pub fn validate(&self) -> Result<()> {
        let problem = if self.pnp_iterations == 0 || self.pnp_iterations > 1000 {
            Some(format!(
                "pnp_iterations {} is not in 1..=1000",
                self.pnp_iterations
            ))
        } else if !(self.bundle_min_spread_deg >= 0.0 && self.bundle_min_spread_deg.is_finite()) {
            Some(format!(
                "bundle_min_spread_deg {} is not a finite angle >= 0",
                self.bundle_min_spread_deg
            ))
        } else if !(2..=MAX_BUNDLE_FRAMES).contains(&self.bundle_frames) {
            Some(format!(
                "bundle_frames {} is not in 2..={MAX_BUNDLE_FRAMES}",
                self.bundle_frames
            ))
        } else if self.bundle_iterations > 1000 {
            Some(format!(
                "bundle_iterations {} is over 1000",
                self.bundle_iterations
            ))
        } else if !(self.bundle_prior_mm > 0.0 && self.bundle_prior_mm.is_finite()) {
            Some(format!(
                "bundle_prior_mm {} is not a finite length > 0",
                self.bundle_prior_mm
            ))
        } else if !(self.smooth_sigma_frames >= 0.0 && self.smooth_sigma_frames.is_finite()) {
            Some(format!(
                "smooth_sigma_frames {} is not finite and >= 0",
                self.smooth_sigma_frames
            ))
        } else if self.smooth_radius_frames > 1000 {
            Some(format!(
                "smooth_radius_frames {} is over 1000",
                self.smooth_radius_frames
            ))
        } else {
            self.track_problem()
        };
        problem.map_or(Ok(()), |p| {
            Err(Error::Argument(format!("pose config: {p}")))
        })
    }

    /// What is wrong with the track fields, if anything.
    fn track_problem(&self) -> Option<String> {
        let positive = |v: f32| v > 0.0 && v.is_finite();
        if self.track_iterations > 1000 {
            Some(format!(
                "track_iterations {} is over 1000",
                self.track_iterations
            ))
        } else if !(3..=MAX_BUNDLE_FRAMES).contains(&self.track_key_frames) {
            Some(format!(
                "track_key_frames {} is not in 3..={MAX_BUNDLE_FRAMES}",
                self.track_key_frames
            ))
        } else if !positive(self.track_huber_px) {
            Some(format!(
                "track_huber_px {} is not a finite length > 0",
                self.track_huber_px
            ))
        } else if !(self.track_reject_factor >= 1.0 && self.track_reject_factor.is_finite()) {
            Some(format!(
                "track_reject_factor {} is not a finite number >= 1",
                self.track_reject_factor
            ))
        } else if !positive(self.track_reject_floor_px) {
            Some(format!(
                "track_reject_floor_px {} is not a finite length > 0",
                self.track_reject_floor_px
            ))
        } else {
            None
        }
    }
}

/// One video frame's face landmarks.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameLandmarks {
    /// Index of the frame in the video.
    pub frame: usize,
    /// Landmarks in pixels (x right, y down), in the canonical face's order: `[n_points]`.
    pub points: Vec<[f32; 2]>,
}

/// The solved camera track, one entry per input frame, in order.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraTrack {
    /// Camera-to-world matrices, OpenGL axes, the face's (canonical) frame as the world.
    pub c2w: Vec<Mat4>,
    /// The 3D face the poses were solved against, metres, canonical frame: `[n_points]`.
    /// Weighted points are the bundle step's (or the canonical ones); the others are the
    /// canonical ones moved as their nearest weighted neighbours moved.
    pub face: Vec<Vec3>,
    /// Whether the bundle step refined the face.
    pub bundled: bool,
    /// The head's motion that decided it: RMS angle (degrees) of the PnP rotations about
    /// their mean.
    pub rotation_spread_deg: f32,
    /// Per frame, the weighted RMS reprojection error in pixels of the returned pose and
    /// face: `sqrt(sum w |project - landmark|^2 / sum w)`.
    pub reprojection_px: Vec<f32>,
    /// What the feature tracks did.
    pub tracks: TrackSummary,
}

/// What the feature tracks did for a [`CameraTrack`] (all zero when they were not used).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct TrackSummary {
    /// Whether the poses come from the tracks (a bundle of their points), else from the
    /// landmarks alone.
    pub bundled: bool,
    /// Tracks whose points the poses were solved against.
    pub tracks_used: usize,
    /// Frames that saw too few of them and took their corrected landmark pose.
    pub frames_on_landmarks: usize,
    /// Median reprojection error of the used tracks' observations, pixels.
    pub residual_px: f32,
}

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

/// `min(n, wanted)` distinct indices spread evenly over `0..n`, both ends included.
fn key_frames(n: usize, wanted: usize) -> Vec<usize> {
    let m = wanted.min(n);
    if m < 2 {
        return (0..m).collect();
    }
    (0..m)
        .map(|i| (i * (n - 1) + (m - 1) / 2) / (m - 1))
        .collect()
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
