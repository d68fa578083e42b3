//! Datasets in AD-NeRF's layout: `transforms_{train,val}.json` with
//! AD-NeRF's field names, frames under `head_imgs/` (or `ori_imgs/`, `gt_imgs/`), the static
//! background `bc.png|jpg`, audio windows `aud.npy` `[N, 16, F]`, optional `parsing/`
//! masks in AD-NeRF's convention, nldf's own `regions/` labels and AD-NeRF's `<id>.lms`
//! landmarks (see [`crate::region`]). Loading validates everything it can without decoding
//! every frame, and every problem is one line naming the file.

use std::path::{Path, PathBuf};

use glam::Mat4;
use serde::{Deserialize, Serialize};

use crate::audio::{
    AudioWindows, FeatureConfig, FeatureSource, audio_windows_for_frames, n_video_frames, read_wav,
};
use crate::camera::{Camera, Intrinsics, rigid_problem};
use crate::error::{Error, Result};
use crate::files::{read_json, write_json};
use crate::image::{ImageRgb, Rect, save_png_bytes};
use crate::landmarks::{LANDMARKS_EXT, Landmarks};
pub use crate::npy::{load_audio_npy, parse_audio_npy, save_audio_npy};
use crate::region::{MouthSource, Region};

/// The audio feature windows, `[N, 16, F]` (AD-NeRF's name).
pub const AUDIO_NPY: &str = "aud.npy";
/// The source audio, mono (ours; AD-NeRF's preprocessing leaves it too).
pub const AUDIO_WAV: &str = "aud.wav";
/// What made `aud.npy` (ours): a [`FeatureSource`] as JSON. Without it, `aud.npy` holds
/// another front end's features (AD-NeRF's DeepSpeech logits, say).
pub const AUDIO_SOURCE_FILE: &str = "aud.json";

/// Which audio features a dataset is read with.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum AudioChoice {
    /// nldf's own features: `aud.npy` when `aud.json` says nldf made it, otherwise
    /// computed from `aud.wav` with the default settings when there is one, otherwise
    /// `aud.npy` as it is (another front end's, which a model then needs at render time).
    #[default]
    Auto,
    /// `aud.npy` as it is, whichever front end made it.
    Npy,
    /// Features made as a trained run's were: `aud.npy` when it was made that way,
    /// otherwise, for nldf's features, computed from `aud.wav`.
    Matching(FeatureSource),
}

/// Folders searched for frames, in order.
pub const IMAGE_DIRS: [&str; 3] = ["head_imgs", "ori_imgs", "gt_imgs"];
/// Image extensions accepted, in order.
pub const IMAGE_EXTS: [&str; 3] = ["png", "jpg", "jpeg"];
/// AD-NeRF's face parsing (head, neck, torso; [`Region::parsing_color`]).
pub const PARSING_DIR: &str = "parsing";
/// nldf's own region labels (face, mouth, eyes; [`Region::label_color`]).
pub const LABELS_DIR: &str = "regions";
/// Where AD-NeRF keeps its landmark files (`<img_id>.lms`); the frames' own folder is
/// searched after it.
pub const LANDMARKS_DIR: &str = "ori_imgs";
/// The synthetic scene's ground truth file in a dataset folder (`nldf synth`, see
/// [`crate::synth`]).
pub const SCENE_FILE: &str = "scene.json";
/// Tolerance of the rigidity check of camera matrices.
pub const RIGID_TOL: f32 = 1e-3;

/// One frame entry of a transforms file, AD-NeRF's fields plus optional ones of ours.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameEntry {
    /// Image file stem under the image folder.
    pub img_id: i64,
    /// Row of `aud.npy` holding this frame's audio window.
    pub aud_id: i64,
    /// 4 x 4 camera-to-world matrix, rows as written in the JSON.
    pub transform_matrix: [[f32; 4]; 4],
    /// Face bounding box `[x, y, w, h]` in pixels; the whole image when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub face_rect: Option<Rect>,
    /// Blink amount of this frame (ours; AD-NeRF's later work uses it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub eye: Option<f32>,
}

/// A `transforms_{train,val}.json` file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TransformsFile {
    /// Focal length in pixels.
    pub focal_len: f32,
    /// Principal point x in pixels.
    pub cx: f32,
    /// Principal point y in pixels.
    pub cy: f32,
    /// Near bound of the rays (ours; AD-NeRF's rule applies when absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub near: Option<f32>,
    /// Far bound of the rays (ours).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub far: Option<f32>,
    /// Video frame rate (ours; 25 when absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fps: Option<f32>,
    /// Image width (ours; the background's when absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub width: Option<u32>,
    /// Image height (ours).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub height: Option<u32>,
    pub frames: Vec<FrameEntry>,
}

impl TransformsFile {
    /// Reads and parses a transforms file (no cross-file checks).
    pub fn load(path: &Path) -> Result<TransformsFile> {
        read_json(path)
    }

    /// Parses a transforms file's text; `path` names it in errors.
    pub fn parse(path: &Path, text: &str) -> Result<TransformsFile> {
        serde_json::from_str(text).map_err(|e| Error::invalid(path, format!("bad JSON: {e}")))
    }

    /// Writes the file atomically, pretty-printed.
    pub fn save(&self, path: &Path) -> Result<()> {
        write_json(path, self)
    }
}

/// Which part of a dataset. `Train` and `Val` are AD-NeRF's; the others are evaluation
/// splits that `nldf synth` writes with exact ground truth and that training never reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Split {
    Train,
    Val,
    /// The held-out frames' audio with the head turned beyond the recorded range, and
    /// seen from a closer and a farther camera.
    Novel,
    /// Held-out speech of another voice driving the head at the held-out poses; its audio
    /// lives in [`VOICE_DIR`].
    Voice,
    /// One held-out frame's audio with the head turned step by step from the front out to
    /// twice the recorded range (the pose-sweep strip).
    Sweep,
}

/// The folder of the `voice` split's audio (`aud.wav`, `aud.npy`, `aud.json`).
pub const VOICE_DIR: &str = "voice";

impl Split {
    /// The transforms file name of the split.
    pub fn file_name(self) -> &'static str {
        match self {
            Split::Train => "transforms_train.json",
            Split::Val => "transforms_val.json",
            Split::Novel => "transforms_novel.json",
            Split::Voice => "transforms_voice.json",
            Split::Sweep => "transforms_sweep.json",
        }
    }

    /// The split's name in lower case (`val`, `novel`).
    pub fn name(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Val => "val",
            Split::Novel => "novel",
            Split::Voice => "voice",
            Split::Sweep => "sweep",
        }
    }

    /// Whether the split is one of the evaluation splits beyond AD-NeRF's two.
    pub fn is_extra(self) -> bool {
        !matches!(self, Split::Train | Split::Val)
    }

    /// The folder, under the dataset's root, of the audio the split's `aud_id`s index.
    pub fn audio_dir(self, root: &Path) -> PathBuf {
        match self {
            Split::Voice => root.join(VOICE_DIR),
            _ => root.to_path_buf(),
        }
    }
}

/// One validated frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    pub img_id: i64,
    /// Row of the audio windows.
    pub aud_id: usize,
    /// Camera-to-world, validated rigid.
    pub c2w: Mat4,
    /// Face box clipped to the image.
    pub face_rect: Rect,
    pub eye: Option<f32>,
    /// The frame's image file (exists).
    pub image_path: PathBuf,
    /// The frame's AD-NeRF parsing mask, when the dataset has one.
    pub parsing_path: Option<PathBuf>,
    /// The frame's nldf region labels, when the dataset has them.
    pub labels_path: Option<PathBuf>,
    /// The frame's 68 landmarks, when the dataset has them.
    pub landmarks_path: Option<PathBuf>,
}

/// A loaded, validated dataset. Frames are decoded on demand ([`Dataset::load_image`]).
#[derive(Debug, Clone)]
pub struct Dataset {
    pub root: PathBuf,
    pub intrinsics: Intrinsics,
    /// Ray bounds: from the transforms file, or AD-NeRF's rule (mean camera distance - 0.2,
    /// + 0.4).
    pub near: f32,
    pub far: f32,
    pub fps: f32,
    pub background: ImageRgb,
    /// One feature window per row of the audio track (see [`AudioChoice`]).
    pub audio: AudioWindows,
    /// Which front end made `audio`.
    pub audio_source: FeatureSource,
    /// The file `audio` was read or computed from (`aud.npy` or `aud.wav`).
    pub audio_file: PathBuf,
    pub train: Vec<Frame>,
    /// The held-out frames: the `val` split's, or those of the split
    /// [`Dataset::load_held_out`] was asked for.
    pub val: Vec<Frame>,
    /// Which split `val` holds.
    pub held_out: Split,
}

fn find_with_ext(dir: &Path, stem: &str) -> Option<PathBuf> {
    IMAGE_EXTS
        .iter()
        .map(|e| dir.join(format!("{stem}.{e}")))
        .find(|p| p.is_file())
}

impl Dataset {
    /// Loads and validates the dataset at `root` with nldf's own audio features where it can
    /// ([`AudioChoice::Auto`]; see [`Dataset::load_with`]).
    pub fn load(root: &Path) -> Result<Dataset> {
        Self::load_with(root, &AudioChoice::Auto)
    }

    /// Loads and validates the dataset at `root`: both transforms files, the background,
    /// the audio features `audio` says, and that every frame's image (and parsing mask, if
    /// `parsing/` exists) is present and every matrix is a finite rigid transform.
    pub fn load_with(root: &Path, audio: &AudioChoice) -> Result<Dataset> {
        if !root.is_dir() {
            return Err(Error::invalid(root, "dataset folder does not exist"));
        }
        let train_file = TransformsFile::load(&root.join(Split::Train.file_name()))?;
        let val_path = root.join(Split::Val.file_name());
        let val_file = TransformsFile::load(&val_path)?;
        let train_path = root.join(Split::Train.file_name());

        let bc_path = find_with_ext(root, "bc").ok_or_else(|| {
            Error::invalid(
                root.join("bc.png"),
                "background image missing (bc.png or bc.jpg)",
            )
        })?;
        let background = ImageRgb::load(&bc_path)?;
        let (width, height) = (background.width, background.height);
        check_intrinsics(&train_path, &train_file, width, height)?;
        let intrinsics = Intrinsics {
            focal: train_file.focal_len,
            cx: train_file.cx,
            cy: train_file.cy,
            width,
            height,
        };
        check_held_out_intrinsics(&val_path, &val_file, &intrinsics)?;

        let fps = train_file.fps.unwrap_or(25.0);
        if !(fps.is_finite() && fps > 0.0) {
            return Err(Error::invalid(
                &train_path,
                format!("fps must be positive, got {fps}"),
            ));
        }
        let n_audio_frames = n_audio_frames(train_file.frames.iter().chain(&val_file.frames));
        let (audio, audio_source, audio_file) = load_audio(root, audio, fps, n_audio_frames)?;
        let dirs = FrameDirs::find(root)?;
        let frames =
            |path: &Path, t: &TransformsFile| validate_frames(path, t, &intrinsics, &audio, &dirs);
        let train = frames(&train_path, &train_file)?;
        let val = frames(&val_path, &val_file)?;
        if train.is_empty() {
            return Err(Error::invalid(&train_path, "has no frames"));
        }

        let (near, far) = match (train_file.near, train_file.far) {
            (Some(n), Some(f)) => (n, f),
            (None, None) => ad_nerf_bounds(&train),
            _ => {
                return Err(Error::invalid(
                    &train_path,
                    "gives only one of `near` and `far`",
                ));
            }
        };
        if !(near.is_finite() && far.is_finite() && near > 0.0 && far > near) {
            return Err(Error::invalid(
                &train_path,
                format!("ray bounds must satisfy 0 < near < far, got near {near}, far {far}"),
            ));
        }
        Ok(Dataset {
            root: root.to_path_buf(),
            intrinsics,
            near,
            far,
            fps,
            background,
            audio,
            audio_source,
            audio_file,
            train,
            val,
            held_out: Split::Val,
        })
    }

    /// Loads the dataset as [`Dataset::load_with`] does, with `split`'s frames held out
    /// instead of `val`'s. For `voice`, the audio is that of [`VOICE_DIR`], read as `audio`
    /// says: the held-out frames index it, so the training frames must not be rendered
    /// with this dataset.
    pub fn load_held_out(root: &Path, audio: &AudioChoice, split: Split) -> Result<Dataset> {
        let mut ds = Self::load_with(root, audio)?;
        if !split.is_extra() {
            return Ok(ds);
        }
        let path = root.join(split.file_name());
        if !path.is_file() {
            return Err(Error::invalid(
                &path,
                format!(
                    "is missing: the {} split is written by `nldf synth` (scenes made by an \
                     earlier version have none; make the scene again)",
                    split.name()
                ),
            ));
        }
        let file = TransformsFile::load(&path)?;
        check_held_out_intrinsics(&path, &file, &ds.intrinsics)?;
        if split == Split::Voice {
            let (audio, source, audio_file) = load_audio(
                &split.audio_dir(root),
                audio,
                ds.fps,
                n_audio_frames(file.frames.iter()),
            )?;
            if source != ds.audio_source {
                return Err(Error::invalid(
                    &audio_file,
                    format!(
                        "holds {}, the dataset's own audio {}",
                        source.describe(),
                        ds.audio_source.describe()
                    ),
                ));
            }
            (ds.audio, ds.audio_source, ds.audio_file) = (audio, source, audio_file);
        }
        ds.val = validate_frames(
            &path,
            &file,
            &ds.intrinsics,
            &ds.audio,
            &FrameDirs::find(root)?,
        )?;
        ds.held_out = split;
        Ok(ds)
    }

    /// The frames of a split: the training frames, or the held-out ones when `split` is
    /// the split held out (empty for any other).
    pub fn frames(&self, split: Split) -> &[Frame] {
        match split {
            Split::Train => &self.train,
            s if s == self.held_out => &self.val,
            _ => &[],
        }
    }

    /// The camera of a frame.
    pub fn camera(&self, frame: &Frame) -> Camera {
        Camera {
            intrinsics: self.intrinsics,
            c2w: frame.c2w,
        }
    }

    /// Decodes a frame's image and checks its size.
    pub fn load_image(&self, frame: &Frame) -> Result<ImageRgb> {
        let img = ImageRgb::load(&frame.image_path)?;
        self.check_size(&frame.image_path, img.width, img.height)?;
        Ok(img)
    }

    /// A frame's regions (`None` when the dataset has neither `regions/` nor `parsing/`):
    /// nldf's labels when present; otherwise AD-NeRF's parsing (head, neck, torso) with the
    /// mouth where the head lies inside the landmarks' outer lip contour when the frame has
    /// landmarks.
    pub fn load_regions(&self, frame: &Frame) -> Result<Option<Vec<Region>>> {
        let decode = |path: &Path, read: fn([u8; 3]) -> Region| -> Result<Vec<Region>> {
            let img = ImageRgb::load(path)?;
            self.check_size(path, img.width, img.height)?;
            Ok(img
                .to_rgb8()
                .chunks_exact(3)
                .map(|c| read([c[0], c[1], c[2]]))
                .collect())
        };
        if let Some(path) = &frame.labels_path {
            return Ok(Some(decode(path, Region::from_label_color)?));
        }
        let Some(path) = &frame.parsing_path else {
            return Ok(None);
        };
        let mut regions = decode(path, Region::from_parsing_color)?;
        if let Some(lms) = &frame.landmarks_path {
            let k = &self.intrinsics;
            let mouth = Landmarks::load(lms)?.mouth_mask(k.width, k.height);
            for (r, m) in regions.iter_mut().zip(mouth) {
                if m && *r == Region::Face {
                    *r = Region::Mouth;
                }
            }
        }
        Ok(Some(regions))
    }

    /// Where the frames' mouth region comes from: nldf's labels, AD-NeRF's landmarks (with
    /// its parsing), or nowhere.
    pub fn mouth_source(&self) -> MouthSource {
        let first = self.train.first().or(self.val.first());
        match first {
            Some(f) if f.labels_path.is_some() => MouthSource::Labels,
            Some(f) if f.parsing_path.is_some() && f.landmarks_path.is_some() => {
                MouthSource::Landmarks
            }
            _ => MouthSource::Unknown,
        }
    }

    fn check_size(&self, path: &Path, w: u32, h: u32) -> Result<()> {
        let k = &self.intrinsics;
        if (w, h) != (k.width, k.height) {
            return Err(Error::invalid(
                path,
                format!(
                    "image is {w}x{h}, the dataset's background is {}x{}",
                    k.width, k.height
                ),
            ));
        }
        Ok(())
    }
}

/// Where a dataset's frame images, masks and landmarks are.
struct FrameDirs {
    /// The first of [`IMAGE_DIRS`] that exists.
    image: PathBuf,
    /// [`PARSING_DIR`], when the dataset has one.
    parsing: Option<PathBuf>,
    /// [`LABELS_DIR`], when the dataset has one.
    labels: Option<PathBuf>,
    /// The first of [`LANDMARKS_DIR`] and the image folder that holds a `.lms` file.
    landmarks: Option<PathBuf>,
}

impl FrameDirs {
    fn find(root: &Path) -> Result<FrameDirs> {
        let image = IMAGE_DIRS
            .iter()
            .map(|d| root.join(d))
            .find(|d| d.is_dir())
            .ok_or_else(|| {
                Error::invalid(
                    root.join("head_imgs"),
                    "no image folder (head_imgs/, ori_imgs/ or gt_imgs/)",
                )
            })?;
        let dir = |name: &str| Some(root.join(name)).filter(|d| d.is_dir());
        let holds_landmarks = |d: &PathBuf| {
            std::fs::read_dir(d).is_ok_and(|entries| {
                entries
                    .flatten()
                    .any(|e| e.path().extension().and_then(|x| x.to_str()) == Some(LANDMARKS_EXT))
            })
        };
        let landmarks = [root.join(LANDMARKS_DIR), image.clone()]
            .into_iter()
            .find(holds_landmarks);
        Ok(FrameDirs {
            parsing: dir(PARSING_DIR),
            labels: dir(LABELS_DIR),
            landmarks,
            image,
        })
    }
}

/// Audio frames the entries need: one past the largest `aud_id`.
fn n_audio_frames<'a>(entries: impl Iterator<Item = &'a FrameEntry>) -> usize {
    entries
        .map(|f| f.aud_id.max(0) as usize + 1)
        .max()
        .unwrap_or(0)
}

/// Every frame of a transforms file, validated ([`validate_frame`]).
fn validate_frames(
    path: &Path,
    t: &TransformsFile,
    k: &Intrinsics,
    audio: &AudioWindows,
    dirs: &FrameDirs,
) -> Result<Vec<Frame>> {
    t.frames
        .iter()
        .enumerate()
        .map(|(n, e)| validate_frame(path, n, e, k, audio, dirs))
        .collect()
}

/// A held-out transforms file's intrinsics: valid, and the training file's.
fn check_held_out_intrinsics(path: &Path, t: &TransformsFile, k: &Intrinsics) -> Result<()> {
    check_intrinsics(path, t, k.width, k.height)?;
    if (t.focal_len, t.cx, t.cy) != (k.focal, k.cx, k.cy) {
        return Err(Error::invalid(
            path,
            "intrinsics differ from transforms_train.json",
        ));
    }
    Ok(())
}

fn check_intrinsics(path: &Path, t: &TransformsFile, width: u32, height: u32) -> Result<()> {
    for (name, v) in [("focal_len", t.focal_len), ("cx", t.cx), ("cy", t.cy)] {
        if !v.is_finite() {
            return Err(Error::invalid(path, format!("`{name}` is not finite")));
        }
    }
    if t.focal_len <= 0.0 {
        return Err(Error::invalid(
            path,
            format!("`focal_len` must be positive, got {}", t.focal_len),
        ));
    }
    if let (Some(w), Some(h)) = (t.width, t.height)
        && (w, h) != (width, height)
    {
        return Err(Error::invalid(
            path,
            format!("says {w}x{h} images but the background bc image is {width}x{height}"),
        ));
    }
    Ok(())
}

fn validate_frame(
    path: &Path,
    n: usize,
    e: &FrameEntry,
    k: &Intrinsics,
    audio: &AudioWindows,
    dirs: &FrameDirs,
) -> Result<Frame> {
    let at = |problem: String| {
        Error::invalid(path, format!("frame {n} (img_id {}): {problem}", e.img_id))
    };
    let c2w = Mat4::from_cols_array_2d(&e.transform_matrix).transpose();
    if let Some(problem) = rigid_problem(&c2w, RIGID_TOL) {
        return Err(at(format!("transform_matrix {problem}")));
    }
    if e.aud_id < 0 || e.aud_id as usize >= audio.n_frames {
        return Err(at(format!(
            "aud_id {} is outside aud.npy's {} audio frames (frame and audio counts do not match)",
            e.aud_id, audio.n_frames
        )));
    }
    let full = Rect {
        x: 0,
        y: 0,
        w: k.width as i64,
        h: k.height as i64,
    };
    let face_rect = match e.face_rect {
        None => full,
        Some(r) => r.clipped(k.width, k.height).ok_or_else(|| {
            at(format!(
                "face_rect {:?} lies outside the image",
                <[i64; 4]>::from(r)
            ))
        })?,
    };
    let stem = e.img_id.to_string();
    let image_dir = &dirs.image;
    let image_path = find_with_ext(image_dir, &stem).ok_or_else(|| {
        at(format!(
            "image {}/{stem}.png|jpg is missing",
            image_dir.display()
        ))
    })?;
    let mask = |dir: &Option<PathBuf>, what: &str| -> Result<Option<PathBuf>> {
        match dir {
            None => Ok(None),
            Some(d) => Some(
                find_with_ext(d, &stem)
                    .ok_or_else(|| at(format!("{what} {}/{stem}.png is missing", d.display()))),
            )
            .transpose(),
        }
    };
    let parsing_path = mask(&dirs.parsing, "parsing mask")?;
    let labels_path = mask(&dirs.labels, "region labels")?;
    let landmarks_path = match &dirs.landmarks {
        None => None,
        Some(d) => {
            let p = d.join(format!("{stem}.{LANDMARKS_EXT}"));
            if !p.is_file() {
                return Err(at(format!("landmarks {} are missing", p.display())));
            }
            Some(p)
        }
    };
    if let Some(eye) = e.eye
        && !eye.is_finite()
    {
        return Err(at("`eye` is not finite".into()));
    }
    Ok(Frame {
        img_id: e.img_id,
        aud_id: e.aud_id as usize,
        c2w,
        face_rect,
        eye: e.eye,
        image_path,
        parsing_path,
        labels_path,
        landmarks_path,
    })
}

/// The audio features of the dataset at `root` as `choice` says (see [`AudioChoice`]),
/// their source and the file they came from. From `aud.wav`, the windows cover the audio
/// and at least `n_frames` video frames at `fps` (a recording a frame short of its video
/// repeats its last window).
pub fn load_audio(
    root: &Path,
    choice: &AudioChoice,
    fps: f32,
    n_frames: usize,
) -> Result<(AudioWindows, FeatureSource, PathBuf)> {
    let npy = root.join(AUDIO_NPY);
    let wav = root.join(AUDIO_WAV);
    let sidecar = read_audio_source(root)?;
    let from_npy = || -> Result<(AudioWindows, FeatureSource, PathBuf)> {
        let windows = load_audio_npy(&npy)?;
        let source = match &sidecar {
            Some(source) => {
                if (source.n_features(), source.window()) != (windows.n_features, windows.window) {
                    return Err(Error::invalid(
                        root.join(AUDIO_SOURCE_FILE),
                        format!(
                            "describes {} x {} windows but {AUDIO_NPY} holds {} x {}",
                            source.window(),
                            source.n_features(),
                            windows.window,
                            windows.n_features
                        ),
                    ));
                }
                source.clone()
            }
            None => FeatureSource::Foreign {
                description: format!(
                    "{AUDIO_NPY} without {AUDIO_SOURCE_FILE}: another front end's features \
                     (AD-NeRF's DeepSpeech logits, say)"
                ),
                n_features: windows.n_features,
                window: windows.window,
            },
        };
        Ok((windows, source, npy.clone()))
    };
    let from_wav = |cfg: &FeatureConfig| -> Result<(AudioWindows, FeatureSource, PathBuf)> {
        let wave = read_wav(&wav)?;
        let have = n_video_frames(wave.samples.len(), wave.sample_rate, fps);
        if have + 1 < n_frames {
            return Err(Error::invalid(
                &wav,
                format!(
                    "{:.2} s of audio make {have} video frames at {fps} fps, but the \
                     transforms use aud_id up to {}",
                    wave.seconds(),
                    n_frames - 1
                ),
            ));
        }
        let windows = audio_windows_for_frames(&wave, fps, cfg, have.max(n_frames))
            .map_err(|e| Error::invalid(&wav, e.to_string()))?;
        Ok((windows, FeatureSource::Nldf(cfg.clone()), wav.clone()))
    };
    let npy_is = |want: &FeatureSource| sidecar.as_ref() == Some(want) && npy.is_file();
    match choice {
        AudioChoice::Npy => from_npy(),
        AudioChoice::Auto => {
            let ours = matches!(sidecar, Some(FeatureSource::Nldf(_)));
            if (ours && npy.is_file()) || !wav.is_file() {
                from_npy()
            } else {
                from_wav(&FeatureConfig::default())
            }
        }
        AudioChoice::Matching(want) => match want {
            _ if npy_is(want) => from_npy(),
            FeatureSource::Nldf(cfg) if wav.is_file() => from_wav(cfg),
            FeatureSource::Nldf(_) => Err(Error::invalid(
                &wav,
                format!(
                    "is missing, and {AUDIO_NPY} does not hold the run's features ({})",
                    want.describe()
                ),
            )),
            FeatureSource::Foreign { .. } => {
                let loaded = from_npy()?;
                if (loaded.0.n_features, loaded.0.window) != (want.n_features(), want.window()) {
                    return Err(Error::invalid(
                        &npy,
                        format!(
                            "holds {} x {} windows, the run was trained on {}",
                            loaded.0.window,
                            loaded.0.n_features,
                            want.describe()
                        ),
                    ));
                }
                Ok(loaded)
            }
        },
    }
}

/// `aud.json` of the dataset at `root`, when it has one.
pub fn read_audio_source(root: &Path) -> Result<Option<FeatureSource>> {
    let path = root.join(AUDIO_SOURCE_FILE);
    if !path.is_file() {
        return Ok(None);
    }
    let source: FeatureSource = read_json(&path)?;
    if let FeatureSource::Nldf(cfg) = &source {
        cfg.validate()
            .map_err(|e| Error::invalid(&path, e.to_string()))?;
    }
    Ok(Some(source))
}

/// Writes audio windows as `aud.npy` and their source as `aud.json` into `dir`, each
/// atomically.
pub fn save_audio_features(
    dir: &Path,
    windows: &AudioWindows,
    source: &FeatureSource,
) -> Result<()> {
    save_audio_npy(&dir.join(AUDIO_NPY), windows)?;
    write_json(&dir.join(AUDIO_SOURCE_FILE), source)
}

/// AD-NeRF's ray bounds: the mean depth of the head's origin along the cameras' viewing
/// axes, minus 0.2 and plus 0.4 (AD-NeRF's preprocessing writes `near = mean_z - 0.2`,
/// `far = mean_z + 0.4`, with `mean_z` the mean z of the tracked head translations in camera
/// space). For a camera-to-world matrix that depth is `z_axis . translation`, which is the
/// camera's distance to the origin only when the camera looks straight at it.
pub fn ad_nerf_bounds(frames: &[Frame]) -> (f32, f32) {
    let mean = frames
        .iter()
        .map(|f| f.c2w.z_axis.truncate().dot(f.c2w.w_axis.truncate()))
        .sum::<f32>()
        / frames.len().max(1) as f32;
    ((mean - 0.2).max(1e-3), mean + 0.4)
}

/// Writes `regions` (row-major) as a PNG of `color`s ([`Region::parsing_color`] for
/// AD-NeRF's `parsing/`, [`Region::label_color`] for nldf's `regions/`), atomically.
pub fn save_regions_png(
    path: &Path,
    width: u32,
    height: u32,
    regions: &[Region],
    color: fn(Region) -> [u8; 3],
) -> Result<()> {
    let bytes: Vec<u8> = regions.iter().flat_map(|r| color(*r)).collect();
    save_png_bytes(path, width, height, image::ExtendedColorType::Rgb8, &bytes)
}
