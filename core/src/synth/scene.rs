//! What a synthetic scene is: its settings ([`SynthConfig`], [`HeadStyle`]), the head's pose
//! in a frame ([`HeadPose`]) and `scene.json`, the ground truth it is written with
//! ([`SceneFile`], one [`SceneFrame`] per recorded frame, one [`EvalFrame`] per frame of the
//! evaluation splits).

use std::path::Path;

use glam::{EulerRot, Mat4, Quat, Vec3};
use serde::{Deserialize, Serialize};

use super::head::HeadParams;
use super::speech::Voice;
use crate::audio::FeatureConfig;
use crate::camera::Intrinsics;
use crate::error::{Error, Result};
use crate::files::{read_json, write_json};

/// Settings of the synthetic scene. Defaults: 12 s of 128 x 128 video at 25 fps (AD-NeRF's
/// frame rate), the camera 1 unit from a head about 0.25 units tall (AD-NeRF's world scale).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SynthConfig {
    /// Seed of the head's look, its voice, its blinks and its motion.
    pub seed: u64,
    /// Length in seconds.
    pub seconds: f32,
    /// Image width and height in pixels.
    pub size: u32,
    /// Sub-pixel rays per pixel along each axis (anti-aliasing; 1 = one ray per pixel).
    pub supersample: u32,
    /// Video frame rate.
    pub fps: f32,
    /// Focal length in pixels for a 128-pixel image (scales with `size`).
    pub focal_at_128: f32,
    /// Distance of the camera from the head's centre.
    pub camera_distance: f32,
    /// Largest head turn (yaw) in degrees; pitch and roll follow at 0.6 and 0.4 of it.
    pub max_yaw_deg: f32,
    /// Largest head shift along each axis, in head units.
    pub max_shift: f32,
    /// Audio features written to `aud.npy`.
    pub features: FeatureConfig,
    /// How far the `novel` split turns the head: this factor times the largest yaw and
    /// pitch of the training frames.
    pub novel_turn: f32,
    /// Seed of the `voice` split's speaker; `seed + 1` when absent.
    pub voice_seed: Option<u64>,
    /// Which head: the standard one the recipes were tuned on, or a second one to prove
    /// them on (see [`HeadStyle`]).
    pub head: HeadStyle,
}

/// Which synthetic head a scene shows.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum HeadStyle {
    /// The head every recipe was tuned on, with nldf's exact region labels (`regions/`).
    #[default]
    Standard,
    /// Another head: longer and narrower, with a fuller head of light hair, another skin
    /// tone, larger ears, and head bounds padded by [`SECOND_HEAD_PAD`] of their size on
    /// each side, so the box holds more background. Labelled as AD-NeRF labels a real
    /// recording: its parsing (head, no mouth) and 68 landmarks per frame
    /// (`ori_imgs/<id>.lms`), without `regions/`; its exact labels, the truth a dataset
    /// prepared from its video is scored against, lie in `truth/regions/`
    /// ([`super::TRUTH_LABELS_DIR`]), where no loader looks.
    Second,
}

/// How much the second head's bounds are padded on each side, as a share of their size.
pub const SECOND_HEAD_PAD: f32 = 0.15;

impl Default for SynthConfig {
    fn default() -> Self {
        SynthConfig {
            seed: 0,
            seconds: 12.0,
            size: 128,
            supersample: 3,
            fps: 25.0,
            focal_at_128: 330.0,
            camera_distance: 1.0,
            max_yaw_deg: 12.0,
            max_shift: 0.015,
            features: FeatureConfig::default(),
            novel_turn: 1.5,
            voice_seed: None,
            head: HeadStyle::Standard,
        }
    }
}

/// The sizes, in pixels, a scene renders at.
pub const SIZES: std::ops::RangeInclusive<u32> = 16..=2048;

/// Checks that a configuration can be rendered.
pub fn validate(cfg: &SynthConfig) -> Result<()> {
    let bad = |m: String| Err(Error::Argument(m));
    if !(cfg.seconds.is_finite() && cfg.seconds > 0.0 && cfg.seconds <= 3600.0) {
        return bad(format!(
            "--seconds must be in (0, 3600], got {}",
            cfg.seconds
        ));
    }
    if !SIZES.contains(&cfg.size) {
        return bad(format!(
            "--size must be in {}..={} pixels, got {}",
            SIZES.start(),
            SIZES.end(),
            cfg.size
        ));
    }
    if !(1..=8).contains(&cfg.supersample) {
        return bad(format!(
            "--supersample must be in 1..=8, got {}",
            cfg.supersample
        ));
    }
    if !(cfg.fps.is_finite() && cfg.fps >= 1.0 && cfg.fps <= 120.0) {
        return bad(format!("fps must be in [1, 120], got {}", cfg.fps));
    }
    if (cfg.seconds * cfg.fps).floor() < 1.0 {
        return bad(format!(
            "{} s at {} fps holds no whole video frame",
            cfg.seconds, cfg.fps
        ));
    }
    let positive = [
        ("focal_at_128", cfg.focal_at_128),
        ("camera_distance", cfg.camera_distance),
    ];
    for (name, v) in positive {
        if !(v.is_finite() && v > 0.0) {
            return bad(format!("{name} must be positive, got {v}"));
        }
    }
    if cfg.camera_distance < 0.5 {
        return bad(format!(
            "camera_distance {} puts the camera inside the head's reach (>= 0.5)",
            cfg.camera_distance
        ));
    }
    for (name, v) in [
        ("max_yaw_deg", cfg.max_yaw_deg),
        ("max_shift", cfg.max_shift),
    ] {
        if !(v.is_finite() && v >= 0.0) {
            return bad(format!("{name} must be >= 0, got {v}"));
        }
    }
    if cfg.max_yaw_deg > 45.0 || cfg.max_shift > 0.1 {
        return bad("head motion is limited to 45 degrees and 0.1 units".into());
    }
    if !(cfg.novel_turn.is_finite() && (1.0..=3.0).contains(&cfg.novel_turn)) {
        return bad(format!(
            "--novel-turn must be in [1, 3] (times the recorded yaw and pitch), got {}",
            cfg.novel_turn
        ));
    }
    cfg.features.validate()
}

/// The rigid head pose of one frame (head-to-world): rotation then translation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HeadPose {
    /// Turn about +y, degrees.
    pub yaw_deg: f32,
    /// Nod about +x, degrees.
    pub pitch_deg: f32,
    /// Tilt about +z, degrees.
    pub roll_deg: f32,
    /// Shift in world units.
    pub translation: [f32; 3],
}

impl HeadPose {
    /// The head-to-world matrix.
    pub fn matrix(&self) -> Mat4 {
        let r = Quat::from_euler(
            EulerRot::YXZ,
            self.yaw_deg.to_radians(),
            self.pitch_deg.to_radians(),
            self.roll_deg.to_radians(),
        );
        Mat4::from_rotation_translation(r, Vec3::from(self.translation))
    }
}

/// Per-frame ground truth in `scene.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneFrame {
    pub img_id: i64,
    /// Time of the frame's start in seconds.
    pub time: f32,
    /// RMS of the frame's audio samples.
    pub loudness: f32,
    /// Mouth opening 0..1.
    pub mouth_open: f32,
    /// Mouth width 0..1 (0.5 neutral).
    pub mouth_width: f32,
    /// Eyelid closure 0..1.
    pub blink: f32,
    /// Head-to-world pose; the frame's camera-to-world (in head space) is its inverse times
    /// the fixed world camera.
    pub pose: HeadPose,
}

/// `scene.json`: how the scene was made and its per-frame ground truth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneFile {
    /// Format marker, so that an output folder can be recognised as an earlier scene.
    pub generator: String,
    pub config: SynthConfig,
    pub head: HeadParams,
    pub voice: Option<Voice>,
    /// The audio's source: `generated` or the path given with `--audio`.
    pub audio_source: String,
    pub intrinsics: Intrinsics,
    /// Depth PNG value per unit of `t`.
    pub depth_scale: f32,
    /// Axis-aligned head bounds in head space (min, max), valid for every face state.
    pub head_bounds: [[f32; 3]; 2],
    pub frames: Vec<SceneFrame>,
    /// The largest |yaw| and |pitch| of the training frames, degrees: the recorded range
    /// that the `novel` and `sweep` splits turn beyond.
    #[serde(default)]
    pub recorded_range_deg: [f32; 2],
    /// Ground truth of the evaluation splits, which training never reads.
    #[serde(default)]
    pub eval_frames: Vec<EvalFrame>,
    /// The `voice` split's speaker.
    #[serde(default)]
    pub eval_voice: Option<Voice>,
}

/// Ground truth of one frame of an evaluation split (`novel`, `voice`, `sweep`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EvalFrame {
    /// The split's name.
    pub split: String,
    pub img_id: i64,
    /// Row of the split's audio features (the recording's, or the `voice/` folder's).
    pub aud_id: i64,
    /// What the view is: on `novel`, `turned 1.5x` (the `novel_turn` factor), `closer` and
    /// `farther`; on `voice`, `recorded pose`; on `sweep`, `turn 0x` to `turn 2x`.
    pub view: String,
    pub mouth_open: f32,
    pub mouth_width: f32,
    pub blink: f32,
    pub pose: HeadPose,
    /// Distance of the camera from the world origin.
    pub camera_distance: f32,
}

/// The `generator` value of `scene.json`.
pub const GENERATOR: &str = "nldf synth 1";

impl SceneFile {
    /// Reads `scene.json`.
    pub fn load(path: &Path) -> Result<SceneFile> {
        read_json(path)
    }

    /// Writes `scene.json`.
    pub(super) fn save(&self, path: &Path) -> Result<()> {
        write_json(path, self)
    }
}
