//! A dataset loaded and validated ([`Dataset`]): its transforms files, background, audio and
//! frames, and AD-NeRF's ray bounds.

use std::path::{Path, PathBuf};

use super::audio::{AudioChoice, load_audio};
use super::layout::{FrameDirs, Split, find_with_ext};
use super::transforms::TransformsFile;
use super::validate::{
    Frame, check_held_out_intrinsics, check_intrinsics, n_audio_frames, validate_frames,
};
use crate::audio::{AudioWindows, FeatureSource};
use crate::camera::{Camera, Intrinsics};
use crate::error::{Error, Result};
use crate::image::ImageRgb;

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
    /// instead of `val`'s. For `voice`, the audio is that of [`VOICE_DIR`](super::VOICE_DIR),
    /// read as `audio` says: the held-out frames index it, so the training frames must not be
    /// rendered with this dataset.
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

    /// Checks that an image of `w` x `h` at `path` has the background's size.
    pub(super) fn check_size(&self, path: &Path, w: u32, h: u32) -> Result<()> {
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
