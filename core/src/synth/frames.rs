//! The scene's frames as the recording and the evaluation splits both make them: the
//! per-frame tracks that drive the head (mouth, eyelids, pose), each drawn from its own
//! stream of the seed, a frame's camera, the audio windows and the transforms files.

use std::f32::consts::PI;

use glam::Vec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::head::FaceState;
use super::scene::{HeadPose, SynthConfig};
use super::speech::{MouthFrame, blink_track, mouth_track};
use crate::audio::{AudioWindows, Waveform, audio_windows};
use crate::camera::{Camera, Intrinsics, look_at};
use crate::dataset::{FrameEntry, TransformsFile};
use crate::error::{Error, Result};

/// A sub-stream of the seed, one per random ingredient.
pub(super) fn stream(seed: u64, id: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(id);
    rng
}

/// A slow, smooth head-motion track: each of yaw, pitch, roll and the three shifts is a sum
/// of three sines of 0.03 to 0.25 Hz with random phases, scaled to its largest value.
fn pose_track(rng: &mut impl Rng, cfg: &SynthConfig, n_frames: usize) -> Vec<HeadPose> {
    let mut channel = |amplitude: f32| {
        let parts: Vec<(f32, f32, f32)> = (0..3)
            .map(|_| {
                (
                    rng.random_range(0.03..0.25f32),
                    rng.random_range(0.0..2.0 * PI),
                    rng.random_range(0.3..1.0f32),
                )
            })
            .collect();
        let total: f32 = parts.iter().map(|p| p.2).sum();
        (0..n_frames)
            .map(|i| {
                let t = i as f32 / cfg.fps;
                let v: f32 = parts
                    .iter()
                    .map(|(f, ph, a)| a * (2.0 * PI * f * t + ph).sin())
                    .sum();
                amplitude * v / total
            })
            .collect::<Vec<f32>>()
    };
    let yaw = channel(cfg.max_yaw_deg);
    let pitch = channel(0.6 * cfg.max_yaw_deg);
    let roll = channel(0.4 * cfg.max_yaw_deg);
    let tx = channel(cfg.max_shift);
    let ty = channel(cfg.max_shift);
    let tz = channel(cfg.max_shift);
    (0..n_frames)
        .map(|i| HeadPose {
            yaw_deg: yaw[i],
            pitch_deg: pitch[i],
            roll_deg: roll[i],
            translation: [tx[i], ty[i], tz[i]],
        })
        .collect()
}

/// The per-frame tracks that drive the head: the mouth, the eyelids and the head pose.
pub(super) struct Tracks {
    pub(super) mouth: Vec<MouthFrame>,
    pub(super) blink: Vec<f32>,
    pub(super) poses: Vec<HeadPose>,
}

impl Tracks {
    /// The mouth follows `wave`; blinks and head motion are drawn from their own streams.
    pub(super) fn new(cfg: &SynthConfig, wave: &Waveform, n_frames: usize) -> Tracks {
        Tracks {
            mouth: mouth_track(wave, cfg.fps, n_frames),
            blink: blink_track(&mut stream(cfg.seed, 4), cfg.fps, n_frames),
            poses: pose_track(&mut stream(cfg.seed, 5), cfg, n_frames),
        }
    }

    /// The number of frames.
    pub(super) fn len(&self) -> usize {
        self.poses.len()
    }

    /// The face state of frame `i`.
    pub(super) fn face(&self, i: usize) -> FaceState {
        FaceState {
            mouth_open: self.mouth[i].mouth_open,
            mouth_width: self.mouth[i].mouth_width,
            blink: self.blink[i],
        }
    }
}

/// The audio features of every video frame, checked to be one per frame.
pub(super) fn feature_windows(
    cfg: &SynthConfig,
    wave: &Waveform,
    n_frames: usize,
) -> Result<AudioWindows> {
    let windows = audio_windows(wave, cfg.fps, &cfg.features)?;
    if windows.n_frames != n_frames {
        return Err(Error::Argument(format!(
            "audio features give {} frames for {n_frames} video frames",
            windows.n_frames
        )));
    }
    Ok(windows)
}

/// The camera in head space of a world camera on +z at `distance`, looking at the origin,
/// with the head in `pose`.
pub(super) fn camera_at(intrinsics: Intrinsics, pose: &HeadPose, distance: f32) -> Camera {
    let world_camera = look_at(Vec3::new(0.0, 0.0, distance), Vec3::ZERO, Vec3::Y);
    Camera {
        intrinsics,
        c2w: pose.matrix().inverse() * world_camera,
    }
}

/// A transforms file of the scene holding `frames`.
pub(super) fn transforms_file(
    cfg: &SynthConfig,
    intrinsics: Intrinsics,
    (near, far): (f32, f32),
    frames: Vec<FrameEntry>,
) -> TransformsFile {
    TransformsFile {
        focal_len: intrinsics.focal,
        cx: intrinsics.cx,
        cy: intrinsics.cy,
        near: Some(near),
        far: Some(far),
        fps: Some(cfg.fps),
        width: Some(cfg.size),
        height: Some(cfg.size),
        frames,
    }
}
