//! The evaluation splits of the synthetic scene, with exact ground truth and never read by
//! training:
//! - `novel`: each held-out frame's audio and face with the head turned beyond the recorded
//!   range ([`SynthConfig::novel_turn`] times the training frames' largest yaw and pitch),
//!   then at its recorded pose from a closer and from a farther camera;
//! - `voice`: speech of another speaker ([`SynthConfig::voice_seed`]) as long as the
//!   held-out frames, driving the mouth at their poses; its audio is written to `voice/`;
//! - `sweep`: the middle held-out frame with the head turned step by step from the front to
//!   twice the recorded range ([`SWEEP_TURNS`]), for the pose-sweep strip.
//!
//! Their images follow the recording's in `head_imgs/` (img_id `n_frames` on).

use std::path::Path;

use super::frames::{Tracks, camera_at, feature_windows, stream, transforms_file};
use super::head::FaceState;
use super::scene::{EvalFrame, HeadPose, SynthConfig};
use super::speech::{MouthFrame, Voice, mouth_track, synthesize_speech};
use crate::audio::{FeatureSource, Waveform, write_wav};
use crate::camera::Intrinsics;
use crate::dataset::{FrameEntry, Split, save_audio_features};
use crate::error::{Error, Result};
use crate::image::Rect;

/// Camera distances of the `novel` split's two unturned views, as factors of the recorded
/// one: closer (the head's bounds stay beyond the rays' near bound) and farther.
pub const NOVEL_DISTANCES: [(&str, f32); 2] = [("closer", 0.93), ("farther", 1.15)];

/// Turns of the `sweep` split, as factors of the recorded largest yaw and pitch.
pub const SWEEP_TURNS: [f32; 7] = [0.0, 0.5, 1.0, 1.25, 1.5, 1.75, 2.0];

/// Frames of the evaluation splits for `n_val` held-out frames.
pub fn n_eval_frames(n_val: usize) -> usize {
    if n_val == 0 {
        return 0;
    }
    n_val * (1 + NOVEL_DISTANCES.len()) + n_val + SWEEP_TURNS.len()
}

/// The evaluation splits of a scene, planned before rendering.
pub struct EvalSplits {
    /// Every frame of every split, in image order (img_id `n_frames` on).
    pub frames: Vec<EvalFrame>,
    /// The training frames' largest |yaw| and |pitch|, degrees.
    pub recorded_range_deg: [f32; 2],
    /// The `voice` split's speaker and audio.
    pub voice: Voice,
    voice_wave: crate::audio::Waveform,
}

impl EvalFrame {
    /// The face state the frame is rendered with.
    pub fn face(&self) -> FaceState {
        FaceState {
            mouth_open: self.mouth_open,
            mouth_width: self.mouth_width,
            blink: self.blink,
        }
    }
}

/// The largest absolute yaw and pitch, in degrees, of the first `n_train` frames' poses.
fn recorded_range(tracks: &Tracks, n_train: usize) -> [f32; 2] {
    let max_abs = |f: fn(&HeadPose) -> f32| {
        tracks.poses[..n_train]
            .iter()
            .map(|p| f(p).abs())
            .fold(0.0f32, f32::max)
    };
    [max_abs(|p| p.yaw_deg), max_abs(|p| p.pitch_deg)]
}

/// Another speaker's voice ([`SynthConfig::voice_seed`]), `n_frames` frames of its speech at
/// the scene's rate, and the mouth track that speech drives.
fn other_voice(cfg: &SynthConfig, n_frames: usize) -> (Voice, Waveform, Vec<MouthFrame>) {
    let voice_seed = cfg.voice_seed.unwrap_or(cfg.seed.wrapping_add(1));
    let rate = cfg.features.sample_rate;
    let n_samples = (n_frames as f64 * rate as f64 / cfg.fps as f64).round() as usize;
    let (voice, voice_wave) = speaker(voice_seed, n_samples, rate);
    let mouth = mouth_track(&voice_wave, cfg.fps, n_frames);
    (voice, voice_wave, mouth)
}

/// The speaker of voice seed `voice_seed` saying `n_samples` samples at `rate`, as 16-bit
/// audio: the `voice` split's speech of a scene whose voice seed it is.
fn speaker(voice_seed: u64, n_samples: usize, rate: u32) -> (Voice, Waveform) {
    let mut rng = stream(voice_seed, 3);
    let voice = Voice::random(&mut rng);
    let wave = synthesize_speech(&mut rng, &voice, n_samples, rate).quantized_16bit();
    (voice, wave)
}

/// Speech of the hidden voice of the synthetic scene of seed `scene_seed` (the `voice`
/// split's speaker, voice seed `scene_seed + 1`), `seconds` long at 16 kHz: what the
/// benchmarks play, so that a model is timed on speech rather than a tone. At the split's
/// length it is the split's audio.
pub fn hidden_voice(scene_seed: u64, seconds: f64) -> Waveform {
    let rate = 16_000;
    speaker(
        scene_seed.wrapping_add(1),
        (seconds * f64::from(rate)).round() as usize,
        rate,
    )
    .1
}

impl EvalSplits {
    /// Plans the splits of a scene whose first `n_train` frames of `tracks` train.
    pub(super) fn new(cfg: &SynthConfig, tracks: &Tracks, n_train: usize) -> Result<EvalSplits> {
        let n = tracks.len();
        let held_out: Vec<usize> = (n_train..n).collect();
        let range = recorded_range(tracks, n_train);
        let sign = |v: f32| if v < 0.0 { -1.0 } else { 1.0 };
        let mut frames = Vec::with_capacity(n_eval_frames(held_out.len()));
        let mut next_id = n as i64;
        let mut push = |split: Split, aud_id: usize, view: String, face: FaceState, pose, d| {
            frames.push(EvalFrame {
                split: split.name().into(),
                img_id: next_id,
                aud_id: aud_id as i64,
                view,
                mouth_open: face.mouth_open,
                mouth_width: face.mouth_width,
                blink: face.blink,
                pose,
                camera_distance: d,
            });
            next_id += 1;
        };
        let d = cfg.camera_distance;
        for &i in &held_out {
            let p = tracks.poses[i];
            let turned = HeadPose {
                yaw_deg: sign(p.yaw_deg) * cfg.novel_turn * range[0],
                pitch_deg: sign(p.pitch_deg) * cfg.novel_turn * range[1],
                ..p
            };
            let view = format!("turned {}x", cfg.novel_turn);
            push(Split::Novel, i, view, tracks.face(i), turned, d);
            for (name, f) in NOVEL_DISTANCES {
                push(Split::Novel, i, name.into(), tracks.face(i), p, f * d);
            }
        }
        // Another speaker, as long as the held-out frames, at their poses and blinks.
        let (voice, voice_wave, mouth) = other_voice(cfg, held_out.len());
        for (k, &i) in held_out.iter().enumerate() {
            let face = FaceState {
                mouth_open: mouth[k].mouth_open,
                mouth_width: mouth[k].mouth_width,
                blink: tracks.blink[i],
            };
            push(
                Split::Voice,
                k,
                "recorded pose".into(),
                face,
                tracks.poses[i],
                d,
            );
        }
        if let Some(&m) = held_out.get(held_out.len() / 2) {
            let p = tracks.poses[m];
            for f in SWEEP_TURNS {
                let pose = HeadPose {
                    yaw_deg: f * range[0],
                    pitch_deg: f * range[1],
                    ..p
                };
                push(
                    Split::Sweep,
                    m,
                    format!("turn {f}x"),
                    tracks.face(m),
                    pose,
                    d,
                );
            }
        }
        Ok(EvalSplits {
            frames,
            recorded_range_deg: range,
            voice,
            voice_wave,
        })
    }

    /// Writes each split's transforms (frame `k` of `frames` has face box `face_rects[k]`)
    /// and the `voice` split's audio and features.
    pub(super) fn write(
        &self,
        cfg: &SynthConfig,
        dir: &Path,
        intrinsics: Intrinsics,
        near_far: (f32, f32),
        face_rects: &[Rect],
    ) -> Result<()> {
        for split in [Split::Novel, Split::Voice, Split::Sweep] {
            let entries = self
                .frames
                .iter()
                .zip(face_rects)
                .filter(|(f, _)| f.split == split.name())
                .map(|(f, rect)| FrameEntry {
                    img_id: f.img_id,
                    aud_id: f.aud_id,
                    transform_matrix: camera_at(intrinsics, &f.pose, f.camera_distance)
                        .c2w
                        .transpose()
                        .to_cols_array_2d(),
                    face_rect: Some(*rect),
                    eye: Some(f.blink),
                })
                .collect();
            transforms_file(cfg, intrinsics, near_far, entries)
                .save(&dir.join(split.file_name()))?;
        }
        let voice_dir = Split::Voice.audio_dir(dir);
        std::fs::create_dir(&voice_dir).map_err(|e| Error::io(&voice_dir, e))?;
        let n_voice = self.frames.iter().filter(|f| f.split == "voice").count();
        write_wav(&voice_dir.join(crate::dataset::AUDIO_WAV), &self.voice_wave)?;
        if n_voice > 0 {
            let windows = feature_windows(cfg, &self.voice_wave, n_voice)?;
            save_audio_features(
                &voice_dir,
                &windows,
                &FeatureSource::Nldf(cfg.features.clone()),
            )?;
        }
        Ok(())
    }
}
