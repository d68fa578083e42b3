//! A dataset's frames validated: every matrix a finite rigid transform, every `aud_id` inside
//! the audio, every face box inside the image, and every file a frame names present; every
//! problem is one line naming the transforms file and the frame.

use std::path::{Path, PathBuf};

use glam::Mat4;

use super::layout::{FrameDirs, find_with_ext};
use super::transforms::{FrameEntry, TransformsFile};
use crate::audio::AudioWindows;
use crate::camera::{Intrinsics, rigid_problem};
use crate::error::{Error, Result};
use crate::image::Rect;
use crate::landmarks::LANDMARKS_EXT;

/// Tolerance of the rigidity check of camera matrices.
pub const RIGID_TOL: f32 = 1e-3;

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

/// Audio frames the entries need: one past the largest `aud_id`.
pub(super) fn n_audio_frames<'a>(entries: impl Iterator<Item = &'a FrameEntry>) -> usize {
    entries
        .map(|f| f.aud_id.max(0) as usize + 1)
        .max()
        .unwrap_or(0)
}

/// Every frame of a transforms file, validated ([`validate_frame`]).
pub(super) fn validate_frames(
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
pub(super) fn check_held_out_intrinsics(
    path: &Path,
    t: &TransformsFile,
    k: &Intrinsics,
) -> Result<()> {
    check_intrinsics(path, t, k.width, k.height)?;
    if (t.focal_len, t.cx, t.cy) != (k.focal, k.cx, k.cy) {
        return Err(Error::invalid(
            path,
            "intrinsics differ from transforms_train.json",
        ));
    }
    Ok(())
}

pub(super) fn check_intrinsics(
    path: &Path,
    t: &TransformsFile,
    width: u32,
    height: u32,
) -> Result<()> {
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
    let face_rect = clipped_face_rect(e, k, at)?;
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

/// A frame's face box clipped to the image, the whole image when the frame gives none; `at`
/// names the frame in the error when the box lies outside the image.
fn clipped_face_rect(e: &FrameEntry, k: &Intrinsics, at: impl Fn(String) -> Error) -> Result<Rect> {
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
    Ok(face_rect)
}
