//! The pose solver's settings, its input and its output: the types every step of
//! [`crate::pose`] shares, so that the steps depend on this module and not on each other's
//! parent.

use glam::{Mat4, Vec3};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

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
    /// How far above the face's outline (the hull of mediapipe's 468 landmarks, up to the
    /// hairline) features are tracked, as a share of the face's height (default 0.5: the
    /// forehead and the hair). 0 keeps them off the hair, which slides and sways over the
    /// head; that posed the tuning videos at 512 pixels better and the test videos worse
    /// (docs/prepare.md), so the default stays.
    pub track_reach: f32,
    /// Frames analysed at fewer pixels than this are decoded again at this size, scaled
    /// up, and the head's pose alone is solved from those (default 256; 0 turns it off).
    /// The tracker finds more corners and follows them back in time from 256 pixels up:
    /// on the tuning videos at 128 pixels the mean rotation error fell from 2.22 to 1.25
    /// degrees (docs/prepare.md). The landmarks, parsing and frames stay the video's own:
    /// in frames scaled up and back down the lips shrank and the head blurred.
    pub pose_size: u32,
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
            track_reach: 0.5,
            pose_size: 256,
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
        } else if self.pose_size > 2048 {
            Some(format!("pose_size {} is over 2048", self.pose_size))
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
        } else if !(0.0..=2.0).contains(&self.track_reach) {
            Some(format!(
                "track_reach {} is not a share of the face's height in 0..=2",
                self.track_reach
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

/// `min(n, wanted)` distinct indices spread evenly over `0..n`, both ends included.
pub(crate) fn key_frames(n: usize, wanted: usize) -> Vec<usize> {
    let m = wanted.min(n);
    if m < 2 {
        return (0..m).collect();
    }
    (0..m)
        .map(|i| (i * (n - 1) + (m - 1) / 2) / (m - 1))
        .collect()
}
