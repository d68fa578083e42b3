//! The synthetic talking head: a procedural head rendered by sphere tracing a signed distance
//! field, with a mouth driven by its own speech-like audio, written as an AD-NeRF dataset
//! whose ground truth (mouth opening, blink, head pose, depth) is known exactly.
//!
//! [`generate`] draws everything random up front from the seed (head, background, voice,
//! blinks, head motion; one ChaCha stream each, so that `--audio` leaves the head as it
//! was), renders the frames in parallel, and writes the dataset into a staging folder that
//! replaces the output only once it is complete.

mod frames;
pub mod head;
mod head_params;
mod head_parts;
mod scene;
mod sdf;
pub mod speech;
mod splits;
pub use splits::hidden_voice;
pub mod trace;

use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::audio::{AudioWindows, FeatureSource, Waveform, resample, write_wav};
use crate::camera::{Camera, Intrinsics};
use crate::dataset::{
    FrameEntry, LABELS_DIR, LANDMARKS_DIR, PARSING_DIR, SCENE_FILE, Split, save_audio_features,
    save_regions_png,
};
use crate::error::{Error, Result};
use crate::image::{ImageRgb, Rect, save_png_bytes};
use crate::landmarks::{LANDMARKS_EXT, Landmarks, landmarks_from_regions};
use crate::region::Region;
use frames::{Tracks, camera_at, feature_windows, stream, transforms_file};
use head::{FaceState, HeadParams, head_bounds};
pub use scene::{
    EvalFrame, GENERATOR, HeadPose, HeadStyle, SECOND_HEAD_PAD, SIZES, SceneFile, SceneFrame,
    SynthConfig, validate,
};
use speech::{Voice, synthesize_speech};
use trace::{HeadFrame, render_background, render_head};

/// Depth PNGs store `t * DEPTH_SCALE` as 16-bit integers (0 where the ray misses).
pub const DEPTH_SCALE: f32 = 10_000.0;

/// Where the second head keeps its exact region labels (nldf's `regions/` palette, one
/// `<img_id>.png` per frame): ground truth for scoring a dataset prepared from its video
/// (the mouth above all), out of the loader's sight, which reads that head's mouth from
/// its landmarks as it would a recording's. The standard head's truth is `regions/`.
pub const TRUTH_LABELS_DIR: &str = "truth/regions";

/// The folder of a scene's exact region labels: `regions/` for the standard head,
/// [`TRUTH_LABELS_DIR`] for the second.
pub fn truth_labels_dir(head: HeadStyle) -> &'static str {
    match head {
        HeadStyle::Standard => LABELS_DIR,
        HeadStyle::Second => TRUTH_LABELS_DIR,
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
    for sub in [
        "head_imgs",
        PARSING_DIR,
        labels,
        truth_labels_dir(cfg.head),
        "depth",
    ] {
        let d = dir.join(sub);
        std::fs::create_dir_all(&d).map_err(|e| Error::io(&d, e))?;
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
/// nldf's exact labels of the head's parts (`regions/`, or [`TRUTH_LABELS_DIR`] for the
/// second head, which also gets 68 landmarks) and depth (`t * DEPTH_SCALE` as 16 bits).
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
    save_regions_png(
        &dir.join(format!("{}/{i}.png", truth_labels_dir(cfg.head))),
        size,
        size,
        &frame.regions,
        Region::label_color,
    )?;
    match cfg.head {
        HeadStyle::Standard => {}
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
    .chain((cfg.head == HeadStyle::Second).then_some((TRUTH_LABELS_DIR, n_frames)))
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
