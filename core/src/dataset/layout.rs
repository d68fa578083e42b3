//! Where a dataset's files lie: the folders and file names of AD-NeRF's layout (and nldf's
//! additions), the splits and their transforms files, and the folders a dataset's frames are
//! found in.

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::landmarks::LANDMARKS_EXT;

/// Folders searched for frames, in order.
pub const IMAGE_DIRS: [&str; 3] = ["head_imgs", "ori_imgs", "gt_imgs"];
/// Image extensions accepted, in order.
pub const IMAGE_EXTS: [&str; 3] = ["png", "jpg", "jpeg"];
/// AD-NeRF's face parsing (head, neck, torso; [`Region::parsing_color`](crate::region::Region::parsing_color)).
pub const PARSING_DIR: &str = "parsing";
/// nldf's own region labels (face, mouth, eyes; [`Region::label_color`](crate::region::Region::label_color)).
pub const LABELS_DIR: &str = "regions";
/// Where AD-NeRF keeps its landmark files (`<img_id>.lms`); the frames' own folder is
/// searched after it.
pub const LANDMARKS_DIR: &str = "ori_imgs";
/// The synthetic scene's ground truth file in a dataset folder (`nldf synth`, see
/// [`crate::synth`]).
pub const SCENE_FILE: &str = "scene.json";

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

/// The first of `<stem>.png|jpg|jpeg` in `dir` that exists.
pub(super) fn find_with_ext(dir: &Path, stem: &str) -> Option<PathBuf> {
    IMAGE_EXTS
        .iter()
        .map(|e| dir.join(format!("{stem}.{e}")))
        .find(|p| p.is_file())
}

/// Where a dataset's frame images, masks and landmarks are.
pub(super) struct FrameDirs {
    /// The first of [`IMAGE_DIRS`] that exists.
    pub(super) image: PathBuf,
    /// [`PARSING_DIR`], when the dataset has one.
    pub(super) parsing: Option<PathBuf>,
    /// [`LABELS_DIR`], when the dataset has one.
    pub(super) labels: Option<PathBuf>,
    /// The first of [`LANDMARKS_DIR`] and the image folder that holds a `.lms` file.
    pub(super) landmarks: Option<PathBuf>,
}

impl FrameDirs {
    /// The folders of the dataset at `root`; an error when it has no image folder.
    pub(super) fn find(root: &Path) -> Result<FrameDirs> {
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
