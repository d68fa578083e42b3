//! A dataset's recording (each train and val frame's camera, and the focal length) read
//! from its transforms files, and a prepared recording aligned onto the truth's.

use std::collections::BTreeMap;
use std::path::Path;

use glam::Mat4;
use nldf_core::camera::rigid_problem;
use nldf_core::dataset::{RIGID_TOL, Split, TransformsFile};

use crate::align::{CameraPose, TrackAlignment, align_tracks};
use crate::error::{Error, Result};

/// The `img_id`s the recording `track` of the prepared dataset at `prepared` shares with the
/// truth's, and the alignment of its cameras onto the truth's over them; an error naming
/// the prepared transforms when none is shared.
pub(crate) fn align_prepared(
    true_track: &Track,
    track: &Track,
    prepared: &Path,
) -> Result<(Vec<i64>, TrackAlignment)> {
    let compared: Vec<i64> = (track.poses.keys())
        .filter(|id| true_track.poses.contains_key(id))
        .copied()
        .collect();
    if compared.is_empty() {
        return Err(Error::invalid(
            prepared.join(Split::Train.file_name()),
            format!(
                "no img_id in common with the truth's {} frames",
                true_track.poses.len()
            ),
        ));
    }
    let poses = align_tracks(&true_track.cameras(&compared), &track.cameras(&compared))?;
    Ok((compared, poses))
}

/// A dataset's recording: each train and val frame's camera by `img_id`, and the focal
/// length.
pub(crate) struct Track {
    pub(crate) poses: BTreeMap<i64, CameraPose>,
    pub(crate) focal: f64,
}

impl Track {
    /// The cameras of frames `ids`, each of which the track has.
    fn cameras(&self, ids: &[i64]) -> Vec<CameraPose> {
        ids.iter().map(|id| self.poses[id]).collect()
    }
}

/// Reads `transforms_train.json` and `transforms_val.json` of `root`.
pub(crate) fn read_track(root: &Path) -> Result<Track> {
    let mut poses = BTreeMap::new();
    let mut focal = None;
    for split in [Split::Train, Split::Val] {
        let path = root.join(split.file_name());
        let t = TransformsFile::load(&path)?;
        if !(t.focal_len.is_finite() && t.focal_len > 0.0) {
            return Err(Error::invalid(
                &path,
                format!("focal_len {} is not positive", t.focal_len),
            ));
        }
        focal.get_or_insert(t.focal_len as f64);
        for f in &t.frames {
            let m = Mat4::from_cols_array_2d(&f.transform_matrix).transpose();
            if let Some(problem) = rigid_problem(&m, RIGID_TOL) {
                return Err(Error::invalid(
                    &path,
                    format!("img_id {}: transform_matrix {problem}", f.img_id),
                ));
            }
            if poses
                .insert(f.img_id, CameraPose::from_rows(&f.transform_matrix))
                .is_some()
            {
                return Err(Error::invalid(
                    &path,
                    format!(
                        "img_id {} appears twice in the train and val files",
                        f.img_id
                    ),
                ));
            }
        }
    }
    Ok(Track {
        poses,
        focal: focal.unwrap_or(1.0),
    })
}
