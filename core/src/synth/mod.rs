//! The synthetic talking head: a procedural head rendered by sphere tracing a signed distance
//! field, with a mouth driven by its own speech-like audio, written as an AD-NeRF dataset
//! whose ground truth (mouth opening, blink, head pose, depth) is known exactly.
//!
//! [`generate`] draws everything random up front from the seed (head, background, voice,
//! blinks, head motion; one ChaCha stream each, so that `--audio` leaves the head as it
//! was), renders the frames in parallel, and writes the dataset into a staging folder that
//! replaces the output only once it is complete.

pub mod head;
mod sdf;
pub mod speech;
mod splits;
mod trace;

use std::f32::consts::PI;
use std::path::{Path, PathBuf};

use glam::{EulerRot, Mat4, Quat, Vec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::audio::{
    AudioWindows, FeatureConfig, FeatureSource, Waveform, audio_windows, resample, write_wav,
};
use crate::camera::{Camera, Intrinsics, look_at};
use crate::dataset::{
    FrameEntry, LABELS_DIR, LANDMARKS_DIR, PARSING_DIR, Split, TransformsFile, save_audio_features,
    save_regions_png,
};
use crate::error::{Error, Result};
use crate::files::{read_json, write_json};
use crate::image::{ImageRgb, save_png_bytes};
use crate::landmarks::{LANDMARKS_EXT, Landmarks, landmarks_from_regions};
use crate::rays::Rect;
use crate::region::Region;
use head::{FaceState, HeadFrame, HeadParams, head_bounds, render_background, render_head};
use speech::{MouthFrame, Voice, blink_track, mouth_track, synthesize_speech};

/// Depth PNGs store `t * DEPTH_SCALE` as 16-bit integers (0 where the ray misses).
pub const DEPTH_SCALE: f32 = 10_000.0;

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
    /// (`ori_imgs/<id>.lms`), without `regions/`.
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

/// Checks that a configuration can be rendered.
pub fn validate(cfg: &SynthConfig) -> Result<()> {
    let bad = |m: String| Err(Error::Argument(m));
    if !(cfg.seconds.is_finite() && cfg.seconds > 0.0 && cfg.seconds <= 3600.0) {
        return bad(format!(
            "--seconds must be in (0, 3600], got {}",
            cfg.seconds
        ));
    }
    if !(16..=2048).contains(&cfg.size) {
        return bad(format!(
            "--size must be in 16..=2048 pixels, got {}",
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

/// The synthetic scene's ground truth file in a dataset folder.
pub const SCENE_FILE: &str = "scene.json";

/// The `generator` value of `scene.json`.
pub const GENERATOR: &str = "nldf synth 1";

impl SceneFile {
    /// Reads `scene.json`.
    pub fn load(path: &Path) -> Result<SceneFile> {
        read_json(path)
    }

    fn save(&self, path: &Path) -> Result<()> {
        write_json(path, self)
    }
}

/// What each frame of an evaluation split is, by `img_id` (`novel`: `turned 1.5x`, `closer`,
/// `farther`; `voice`: `recorded pose`; `sweep`: `turn 0x` to `turn 2x`), from the scene
/// file of the dataset at `root`; empty when the dataset has no [`SCENE_FILE`] (a recorded
/// dataset).
pub fn eval_views(root: &Path, split: &str) -> Result<std::collections::HashMap<i64, String>> {
    let path = root.join(SCENE_FILE);
    if !path.is_file() {
        return Ok(Default::default());
    }
    Ok(SceneFile::load(&path)?
        .eval_frames
        .into_iter()
        .filter(|f| f.split == split)
        .map(|f| (f.img_id, f.view))
        .collect())
}

/// What [`generate`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    pub out: PathBuf,
    pub n_frames: usize,
    pub n_train: usize,
    /// Frames of the evaluation splits (`novel`, `voice`, `sweep`).
    pub n_eval: usize,
    /// The files and folders written, relative to `out`, with the number of files in each
    /// (1 for a file).
    pub files: Vec<(PathBuf, usize)>,
}

/// The number of frames [`generate`] renders for `cfg`: the recording's, then those of the
/// evaluation splits.
pub fn frames_rendered(cfg: &SynthConfig) -> usize {
    let n = (cfg.seconds * cfg.fps).floor() as usize;
    n + splits::n_eval_frames(n - n_train(n))
}

/// Training frames of a scene of `n_frames`: the first ten elevenths, at least one.
fn n_train(n_frames: usize) -> usize {
    (n_frames * 10 / 11).max(1).min(n_frames)
}

/// Whether `out` may be replaced: absent, empty, an earlier scene, or `force`.
fn check_output(out: &Path, force: bool) -> Result<()> {
    if !out.exists() {
        return Ok(());
    }
    if !out.is_dir() {
        return Err(Error::invalid(out, "exists and is not a folder"));
    }
    let empty = std::fs::read_dir(out)
        .map_err(|e| Error::io(out, e))?
        .next()
        .is_none();
    let earlier_scene = SceneFile::load(&out.join(SCENE_FILE))
        .map(|s| s.generator == GENERATOR)
        .unwrap_or(false);
    if empty || earlier_scene || force {
        Ok(())
    } else {
        Err(Error::invalid(
            out,
            "folder is not empty and holds no earlier synthetic scene; pass --force to replace it",
        ))
    }
}

/// Generates the synthetic scene into `out` (see the module docs). `audio`, when given,
/// drives the mouth instead of generated speech and is cut to `cfg.seconds`. `tick` is
/// called once per rendered frame, from any thread. `out` must be absent, empty or an
/// earlier scene unless `force`; on failure it is left as it was.
pub fn generate(
    cfg: &SynthConfig,
    audio: Option<Waveform>,
    out: &Path,
    force: bool,
    tick: &(dyn Fn() + Sync),
) -> Result<Summary> {
    validate(cfg)?;
    check_output(out, force)?;
    let name = out
        .file_name()
        .ok_or_else(|| Error::invalid(out, "not a folder path"))?
        .to_string_lossy()
        .into_owned();
    let parent = out
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
    let staging = parent.join(format!(".{name}.staging-{}", std::process::id()));
    if staging.exists() {
        std::fs::remove_dir_all(&staging).map_err(|e| Error::io(&staging, e))?;
    }
    std::fs::create_dir(&staging).map_err(|e| Error::io(&staging, e))?;
    let written = write_scene(cfg, audio, &staging, tick);
    let summary = match written {
        Ok(s) => s,
        Err(e) => {
            let _ = std::fs::remove_dir_all(&staging);
            return Err(e);
        }
    };
    let old = parent.join(format!(".{name}.old-{}", std::process::id()));
    if out.exists() {
        std::fs::rename(out, &old).map_err(|e| {
            let _ = std::fs::remove_dir_all(&staging);
            Error::io(out, e)
        })?;
    }
    if let Err(e) = std::fs::rename(&staging, out) {
        let _ = std::fs::rename(&old, out);
        let _ = std::fs::remove_dir_all(&staging);
        return Err(Error::io(out, e));
    }
    if old.exists() {
        std::fs::remove_dir_all(&old).map_err(|e| Error::io(&old, e))?;
    }
    Ok(Summary {
        out: out.to_path_buf(),
        ..summary
    })
}

/// A sub-stream of the seed, one per random ingredient.
fn stream(seed: u64, id: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(id);
    rng
}

/// Writes the scene into `dir`: draws the head, the background, the audio and the per-frame
/// tracks, then writes the inputs, the rendered frames, the transforms and `scene.json`.
fn write_scene(
    cfg: &SynthConfig,
    audio: Option<Waveform>,
    dir: &Path,
    tick: &(dyn Fn() + Sync),
) -> Result<Summary> {
    let n_frames = (cfg.seconds * cfg.fps).floor() as usize;
    let head = match cfg.head {
        HeadStyle::Standard => HeadParams::random(&mut stream(cfg.seed, 1)),
        HeadStyle::Second => HeadParams::second(&mut stream(cfg.seed, 1)),
    };
    let background = render_background(&mut stream(cfg.seed, 2), cfg.size, cfg.size);
    let (voice, audio_source, wave) = scene_audio(cfg, audio, n_frames)?;
    let tracks = Tracks::new(cfg, &wave, n_frames);
    let windows = feature_windows(cfg, &wave, n_frames)?;
    let (intrinsics, cameras) = frame_cameras(cfg, &tracks.poses);
    write_inputs(cfg, dir, &background, &wave, &windows)?;
    let n_train = n_train(n_frames);
    let extra = splits::EvalSplits::new(cfg, &tracks, n_train)?;
    let mut views: Vec<(FaceState, Camera)> = (0..n_frames)
        .map(|i| (tracks.face(i), cameras[i]))
        .collect();
    views.extend(
        extra
            .frames
            .iter()
            .map(|f| (f.face(), camera_at(intrinsics, &f.pose, f.camera_distance))),
    );
    let face_rects = render_frames(cfg, dir, &head, &background, &views, tick)?;
    let (near, far) = near_far(&cameras);
    write_transforms(
        cfg,
        dir,
        intrinsics,
        (near, far),
        &cameras,
        &face_rects[..n_frames],
        &tracks.blink,
    )?;
    extra.write(cfg, dir, intrinsics, (near, far), &face_rects[n_frames..])?;
    let mut scene = scene_file(cfg, head, voice, audio_source, intrinsics, &tracks);
    scene.recorded_range_deg = extra.recorded_range_deg;
    scene.eval_frames = extra.frames.clone();
    scene.eval_voice = Some(extra.voice.clone());
    scene.save(&dir.join(SCENE_FILE))?;
    Ok(Summary {
        out: dir.to_path_buf(),
        n_frames,
        n_train,
        n_eval: extra.frames.len(),
        files: scene_files(cfg, n_frames + extra.frames.len()),
    })
}

/// The audio of a scene of `n_frames` frames as `aud.wav` stores it (16-bit), with the voice
/// that spoke it and its `audio_source`: speech generated from the seed, or `audio`
/// resampled and cut to length (no voice).
fn scene_audio(
    cfg: &SynthConfig,
    audio: Option<Waveform>,
    n_frames: usize,
) -> Result<(Option<Voice>, String, Waveform)> {
    let rate = cfg.features.sample_rate;
    let n_samples = (n_frames as f64 * rate as f64 / cfg.fps as f64).round() as usize;
    let (voice, audio_source, wave) = match audio {
        None => {
            let mut rng = stream(cfg.seed, 3);
            let voice = Voice::random(&mut rng);
            let wave = synthesize_speech(&mut rng, &voice, n_samples, rate);
            (Some(voice), "generated".to_string(), wave)
        }
        Some(w) => {
            let w = resample(&w, rate);
            if w.samples.len() < n_samples {
                return Err(Error::Argument(format!(
                    "the audio lasts {:.2} s, shorter than the {} s asked for",
                    w.seconds(),
                    cfg.seconds
                )));
            }
            (None, "file".to_string(), w.truncated(n_samples))
        }
    };
    // Features and the mouth are computed from the audio exactly as aud.wav stores it.
    Ok((voice, audio_source, wave.quantized_16bit()))
}

/// The per-frame tracks that drive the head: the mouth, the eyelids and the head pose.
struct Tracks {
    mouth: Vec<MouthFrame>,
    blink: Vec<f32>,
    poses: Vec<HeadPose>,
}

impl Tracks {
    /// The mouth follows `wave`; blinks and head motion are drawn from their own streams.
    fn new(cfg: &SynthConfig, wave: &Waveform, n_frames: usize) -> Tracks {
        Tracks {
            mouth: mouth_track(wave, cfg.fps, n_frames),
            blink: blink_track(&mut stream(cfg.seed, 4), cfg.fps, n_frames),
            poses: pose_track(&mut stream(cfg.seed, 5), cfg, n_frames),
        }
    }

    /// The number of frames.
    fn len(&self) -> usize {
        self.poses.len()
    }

    /// The face state of frame `i`.
    fn face(&self, i: usize) -> FaceState {
        FaceState {
            mouth_open: self.mouth[i].mouth_open,
            mouth_width: self.mouth[i].mouth_width,
            blink: self.blink[i],
        }
    }
}

/// The audio features of every video frame, checked to be one per frame.
fn feature_windows(cfg: &SynthConfig, wave: &Waveform, n_frames: usize) -> Result<AudioWindows> {
    let windows = audio_windows(wave, cfg.fps, &cfg.features)?;
    if windows.n_frames != n_frames {
        return Err(Error::Argument(format!(
            "audio features give {} frames for {n_frames} video frames",
            windows.n_frames
        )));
    }
    Ok(windows)
}

/// The intrinsics, and each frame's camera in head space: the fixed world camera on +z looking
/// at the origin, seen from the head in that frame's pose.
fn frame_cameras(cfg: &SynthConfig, poses: &[HeadPose]) -> (Intrinsics, Vec<Camera>) {
    let s = cfg.size as f32;
    let intrinsics = Intrinsics {
        focal: cfg.focal_at_128 * s / 128.0,
        cx: s / 2.0,
        cy: s / 2.0,
        width: cfg.size,
        height: cfg.size,
    };
    let cameras = poses
        .iter()
        .map(|p| camera_at(intrinsics, p, cfg.camera_distance))
        .collect();
    (intrinsics, cameras)
}

/// The camera in head space of a world camera on +z at `distance`, looking at the origin,
/// with the head in `pose`.
fn camera_at(intrinsics: Intrinsics, pose: &HeadPose, distance: f32) -> Camera {
    let world_camera = look_at(Vec3::new(0.0, 0.0, distance), Vec3::ZERO, Vec3::Y);
    Camera {
        intrinsics,
        c2w: pose.matrix().inverse() * world_camera,
    }
}

/// The rays' near and far bounds: 0.2 before and 0.4 past the cameras' mean distance from
/// the head (AD-NeRF's rule).
fn near_far(cameras: &[Camera]) -> (f32, f32) {
    let mean = cameras.iter().map(|c| c.origin().length()).sum::<f32>() / cameras.len() as f32;
    (mean - 0.2, mean + 0.4)
}

/// Creates the per-frame folders and writes the background, the audio and its features.
fn write_inputs(
    cfg: &SynthConfig,
    dir: &Path,
    background: &ImageRgb,
    wave: &Waveform,
    windows: &AudioWindows,
) -> Result<()> {
    let labels = match cfg.head {
        HeadStyle::Standard => LABELS_DIR,
        HeadStyle::Second => LANDMARKS_DIR,
    };
    for sub in ["head_imgs", PARSING_DIR, labels, "depth"] {
        let d = dir.join(sub);
        std::fs::create_dir(&d).map_err(|e| Error::io(&d, e))?;
    }
    background.save_png(&dir.join("bc.png"))?;
    write_wav(&dir.join("aud.wav"), wave)?;
    save_audio_features(dir, windows, &FeatureSource::Nldf(cfg.features.clone()))
}

/// Renders the views in parallel (view `i` is image `i`), writes each one's files, calls
/// `tick` once per frame and returns each frame's face rectangle.
fn render_frames(
    cfg: &SynthConfig,
    dir: &Path,
    head: &HeadParams,
    background: &ImageRgb,
    views: &[(FaceState, Camera)],
    tick: &(dyn Fn() + Sync),
) -> Result<Vec<Rect>> {
    (0..views.len())
        .into_par_iter()
        .map(|i| {
            let (face, camera) = &views[i];
            let frame = render_head(head, face, camera, background, cfg.supersample);
            write_frame(dir, i, &frame, cfg)?;
            tick();
            Ok(face_rect(&frame.regions, cfg.size))
        })
        .collect()
}

/// Writes frame `i`'s image, its face parsing in AD-NeRF's convention (head, no mouth),
/// nldf's exact labels of the head's parts and depth (`t * DEPTH_SCALE` as 16 bits).
fn write_frame(dir: &Path, i: usize, frame: &HeadFrame, cfg: &SynthConfig) -> Result<()> {
    let size = cfg.size;
    frame
        .rgb
        .save_png(&dir.join(format!("head_imgs/{i}.png")))?;
    save_regions_png(
        &dir.join(format!("{PARSING_DIR}/{i}.png")),
        size,
        size,
        &frame.regions,
        Region::parsing_color,
    )?;
    match cfg.head {
        HeadStyle::Standard => save_regions_png(
            &dir.join(format!("{LABELS_DIR}/{i}.png")),
            size,
            size,
            &frame.regions,
            Region::label_color,
        )?,
        HeadStyle::Second => {
            // A frame without a visible mouth gets its head's centre as every point: a
            // tracker's guess, whose lip polygon covers no pixel.
            let lms = landmarks_from_regions(&frame.regions, size).unwrap_or_else(|| Landmarks {
                points: vec![[size as f32 / 2.0; 2]; crate::landmarks::N_LANDMARKS],
            });
            crate::files::write_atomic(
                &dir.join(format!("{LANDMARKS_DIR}/{i}.{LANDMARKS_EXT}")),
                lms.to_text().as_bytes(),
            )?;
        }
    }
    let depth: Vec<u8> = frame
        .depth
        .iter()
        .flat_map(|&t| ((t * DEPTH_SCALE).round().clamp(0.0, 65535.0) as u16).to_ne_bytes())
        .collect();
    save_png_bytes(
        &dir.join(format!("depth/{i}.png")),
        size,
        size,
        image::ExtendedColorType::L16,
        &depth,
    )
}

/// Writes the train and val transforms (the first ten elevenths of the frames, at least one,
/// train; the rest val) with the rays' `near` and `far` bounds.
fn write_transforms(
    cfg: &SynthConfig,
    dir: &Path,
    intrinsics: Intrinsics,
    (near, far): (f32, f32),
    cameras: &[Camera],
    face_rects: &[Rect],
    blink: &[f32],
) -> Result<()> {
    let n_frames = cameras.len();
    let entries: Vec<FrameEntry> = (0..n_frames)
        .map(|i| FrameEntry {
            img_id: i as i64,
            aud_id: i as i64,
            transform_matrix: cameras[i].c2w.transpose().to_cols_array_2d(),
            face_rect: Some(face_rects[i]),
            eye: Some(blink[i]),
        })
        .collect();
    let n_train = n_train(n_frames);
    let transforms =
        |frames: &[FrameEntry]| transforms_file(cfg, intrinsics, (near, far), frames.to_vec());
    transforms(&entries[..n_train]).save(&dir.join(Split::Train.file_name()))?;
    transforms(&entries[n_train..]).save(&dir.join(Split::Val.file_name()))
}

/// A transforms file of the scene holding `frames`.
fn transforms_file(
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

/// `scene.json`: how the scene was made and every frame's ground truth.
fn scene_file(
    cfg: &SynthConfig,
    head: HeadParams,
    voice: Option<Voice>,
    audio_source: String,
    intrinsics: Intrinsics,
    tracks: &Tracks,
) -> SceneFile {
    let (mut lo, mut hi) = head_bounds(&head);
    if cfg.head == HeadStyle::Second {
        let pad = (hi - lo) * SECOND_HEAD_PAD;
        (lo, hi) = (lo - pad, hi + pad);
    }
    SceneFile {
        generator: GENERATOR.to_string(),
        config: cfg.clone(),
        head,
        voice,
        audio_source,
        intrinsics,
        depth_scale: DEPTH_SCALE,
        head_bounds: [lo.to_array(), hi.to_array()],
        recorded_range_deg: [0.0; 2],
        eval_frames: Vec::new(),
        eval_voice: None,
        frames: (0..tracks.len())
            .map(|i| SceneFrame {
                img_id: i as i64,
                time: i as f32 / cfg.fps,
                loudness: tracks.mouth[i].loudness,
                mouth_open: tracks.mouth[i].mouth_open,
                mouth_width: tracks.mouth[i].mouth_width,
                blink: tracks.blink[i],
                pose: tracks.poses[i],
            })
            .collect(),
    }
}

/// The files and folders of a scene of `n_frames` frames (evaluation splits included), as
/// [`Summary::files`] lists them.
fn scene_files(cfg: &SynthConfig, n_frames: usize) -> Vec<(PathBuf, usize)> {
    let labels = match cfg.head {
        HeadStyle::Standard => LABELS_DIR,
        HeadStyle::Second => LANDMARKS_DIR,
    };
    [
        ("transforms_train.json", 1),
        ("transforms_val.json", 1),
        ("transforms_novel.json", 1),
        ("transforms_voice.json", 1),
        ("transforms_sweep.json", 1),
        ("voice", 3),
        ("bc.png", 1),
        ("aud.wav", 1),
        ("aud.npy", 1),
        ("aud.json", 1),
        ("head_imgs", n_frames),
        (PARSING_DIR, n_frames),
        (labels, n_frames),
        ("depth", n_frames),
        (SCENE_FILE, 1),
    ]
    .into_iter()
    .map(|(p, n)| (PathBuf::from(p), n))
    .collect()
}

/// The bounding box of the head's pixels, padded by 4 % of the image, or the whole image
/// when the head is not in view.
fn face_rect(regions: &[Region], size: u32) -> Rect {
    let n = size as i64;
    let (mut x0, mut y0, mut x1, mut y1) = (n, n, -1, -1);
    for (p, r) in regions.iter().enumerate() {
        if r.is_head() {
            let (i, j) = (p as i64 % n, p as i64 / n);
            x0 = x0.min(i);
            y0 = y0.min(j);
            x1 = x1.max(i);
            y1 = y1.max(j);
        }
    }
    if x1 < 0 {
        return Rect {
            x: 0,
            y: 0,
            w: n,
            h: n,
        };
    }
    let pad = (n as f32 * 0.04).ceil() as i64;
    let r = Rect {
        x: x0 - pad,
        y: y0 - pad,
        w: x1 - x0 + 1 + 2 * pad,
        h: y1 - y0 + 1 + 2 * pad,
    };
    r.clipped(size, size).unwrap_or(Rect {
        x: 0,
        y: 0,
        w: n,
        h: n,
    })
}
