//! A synthetic scene's held-out splits carried into a dataset prepared from its test video,
//! so that a model trained on the prepared dataset is scored on the same turned heads and
//! the same unheard voice as one trained on the scene itself.
//!
//! The prepared cameras live in their own world (scale, orientation and placement no method
//! can observe), so each held-out camera has to be brought into it, in one of two ways
//! ([`Carry`]):
//! - [`Carry::NearestFrame`] (the default): from the recorded frame whose true camera is
//!   nearest (for `voice` and the closer and farther `novel` views, the frame they were
//!   made from), keeping the camera's move relative to it. The held-out camera becomes that
//!   frame's *prepared* camera moved as the true one moved, its shift scaled into the
//!   prepared world by the frame's own distance to the head: the prepared camera's distance
//!   to the head's centre as the prepared views see it ([`seen_centre`]) over the true
//!   camera's distance to the true head's centre (the origin). A turn about the head thus
//!   stays a turn about the head, and a camera twice as far stays twice as far, as when a
//!   user poses the head. (The similarity's scale, used before, takes lengths across the
//!   track; where the prepared track turns less than the truth and stands deeper, the two
//!   differ, and a view turned beyond the recording orbited a point off the head's centre:
//!   6 pixels off at 128 on the standard head's test video, see docs/prepare.md.) A `voice`
//!   frame is thus rendered at the prepared pose of the recorded frame it repeats, as a
//!   user renders new audio on a recorded pose track.
//! - [`Carry::Similarity`]: by the inverse of the one similarity that takes the whole
//!   prepared recording onto the true one ([`crate::align`]), so that every pose error of
//!   the held-out frames' own neighbours shows.
//!
//! The held-out frames' images, parsing and audio are the scene's; their `.lms` are the
//! scene's, or for a scene with exact labels, drawn from its mouth as `nldf synth` draws
//! them.

use std::path::Path;

use glam::{DMat3, DVec3};
use nldf_core::dataset::{Split, TransformsFile};
use nldf_core::landmarks::landmarks_from_regions;
use nldf_core::region::Region;

use crate::align::{CameraPose, rotation_angle_deg};
use crate::check::{read_regions, truth_labels};
use crate::error::{Error, Result};
use crate::recording::{Track, align_prepared, read_track};

/// The held-out splits carried, in this order.
pub const HELD_OUT: [Split; 3] = [Split::Novel, Split::Voice, Split::Sweep];

/// How a held-out camera is brought into the prepared world (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Carry {
    /// From the nearest recorded frame's prepared camera, keeping the move relative to it.
    #[default]
    NearestFrame,
    /// By the inverse of the similarity fitted to the whole recording.
    Similarity,
}

/// Writes the truth's held-out splits into `prepared` (see the module docs), each camera
/// carried as `how` says, and returns the splits it carried. The prepared dataset must use
/// the truth's intrinsics (prepare it with the scene's `--focal`).
pub fn carry_held_out(truth: &Path, prepared: &Path, how: Carry) -> Result<Vec<Split>> {
    let true_track = read_track(truth)?;
    let track = read_track(prepared)?;
    let (shared, alignment) = align_prepared(&true_track, &track, prepared)?;
    let to_prepared = alignment.similarity.inverse();
    let centre = seen_centre(
        &true_track,
        &track,
        &shared,
        to_prepared.apply_point(DVec3::ZERO),
    );
    let carry = |camera: &CameraPose| match how {
        Carry::Similarity => to_prepared.apply(camera),
        Carry::NearestFrame => from_nearest_frame(&true_track, &track, &shared, centre, camera),
    };
    let train_path = prepared.join(Split::Train.file_name());
    let train = TransformsFile::load(&train_path)?;
    if (train.focal_len - true_track.focal as f32).abs() > 1e-3 {
        return Err(Error::invalid(
            &train_path,
            format!(
                "focal_len {} is not the scene's {}: prepare the video with --focal {}",
                train.focal_len, true_track.focal, true_track.focal
            ),
        ));
    }
    for dir in ["head_imgs", "parsing", "ori_imgs"] {
        let d = prepared.join(dir);
        std::fs::create_dir_all(&d).map_err(|e| Error::io(&d, e))?;
    }
    let mut carried = Vec::new();
    for split in HELD_OUT {
        let path = truth.join(split.file_name());
        if !path.is_file() {
            continue;
        }
        let mut held = TransformsFile::load(&path)?;
        for f in &mut held.frames {
            let moved = carry(&CameraPose::from_rows(&f.transform_matrix));
            f.transform_matrix = moved.to_rows();
            copy_frame_files(truth, prepared, f.img_id)?;
        }
        let file = TransformsFile {
            frames: held.frames,
            ..train.clone()
        };
        file.save(&prepared.join(split.file_name()))?;
        if split == Split::Voice {
            copy_dir(&split.audio_dir(truth), &split.audio_dir(prepared))?;
        }
        carried.push(split);
    }
    Ok(carried)
}

/// `camera` (a true held-out camera) carried by [`Carry::NearestFrame`]: the prepared camera
/// of the recorded frame among `ids` nearest it, moved as the true one moves to `camera`,
/// lengths scaled by that frame's distance to the head: `|c^prep - centre| / |c^true|`
/// (`centre` from [`seen_centre`]).
fn from_nearest_frame(
    truth: &Track,
    track: &Track,
    ids: &[i64],
    centre: DVec3,
    camera: &CameraPose,
) -> CameraPose {
    let id = nearest_frame(truth, ids, camera);
    let (prepared, true_from) = (&track.poses[&id], &truth.poses[&id]);
    let scale =
        (prepared.centre - centre).length() / true_from.centre.length().max(f64::MIN_POSITIVE);
    moved_like(prepared, true_from, camera, scale)
}

/// The recorded frame among `ids` whose true camera is nearest `camera`: the angle between
/// the rotations (radians) plus the distance between the centres as a share of the
/// frame's own distance from the origin. `ids` is not empty ([`align_prepared`] refuses).
fn nearest_frame(truth: &Track, ids: &[i64], camera: &CameraPose) -> i64 {
    let distance = |id: &i64| {
        let p = &truth.poses[id];
        let angle = rotation_angle_deg(p.rotation.transpose() * camera.rotation).to_radians();
        angle + (p.centre - camera.centre).length() / p.centre.length().max(f64::MIN_POSITIVE)
    };
    ids.iter()
        .copied()
        .min_by(|a, b| distance(a).total_cmp(&distance(b)))
        .unwrap_or_default()
}

/// The head's centre in the prepared world as its views see it: the point nearest, in least
/// squares, to every frame's prepared ray through the pixel where the true head's centre
/// (the truth's origin) shows in that frame,
/// `argmin_p sum_f |(I - d_f d_f^T)(p - c_f)|^2 + λ n |p - p_0|^2`, with
/// `d_f = R_f^prep (R_f^true)^T (0 - c_f^true) / |c_f^true|`, `n` frames and a weak pull
/// (`λ = 1e-6`) towards `p_0 = prior`, the similarity's image of the origin, that only
/// matters when the rays are nearly parallel (a head that hardly moves). Exact when the
/// prepared track is the truth under a similarity: then every ray passes through `p_0`.
fn seen_centre(truth: &Track, track: &Track, ids: &[i64], prior: DVec3) -> DVec3 {
    const PULL: f64 = 1e-6;
    let pull = PULL * ids.len().max(1) as f64;
    let (mut normal, mut rhs) = (DMat3::IDENTITY * pull, prior * pull);
    for id in ids {
        let (t, p) = (&truth.poses[id], &track.poses[id]);
        let Some(seen) = (t.rotation.transpose() * -t.centre).try_normalize() else {
            continue;
        };
        let d = p.rotation * seen;
        let project = DMat3::IDENTITY - DMat3::from_cols(d * d.x, d * d.y, d * d.z);
        normal += project;
        rhs += project * p.centre;
    }
    // Positive definite: the pull alone is, and each projection is semidefinite.
    normal.inverse() * rhs
}

/// `prepared` (a frame's prepared camera) moved as the true camera of the same frame,
/// `true_from`, moves to `true_to`: the same rotation relative to the camera, and the same
/// shift in the camera's own axes, times `scale` (true world lengths into prepared ones).
pub fn moved_like(
    prepared: &CameraPose,
    true_from: &CameraPose,
    true_to: &CameraPose,
    scale: f64,
) -> CameraPose {
    let back = true_from.rotation.transpose();
    CameraPose {
        rotation: prepared.rotation * back * true_to.rotation,
        centre: prepared.centre
            + prepared.rotation * (back * (true_to.centre - true_from.centre)) * scale,
    }
}

/// Copies frame `id`'s image and parsing, and its `.lms` (made from the exact labels where
/// the scene has none).
fn copy_frame_files(truth: &Path, prepared: &Path, id: i64) -> Result<()> {
    for (from, to) in [("head_imgs", "head_imgs"), ("parsing", "parsing")] {
        let src = truth.join(from).join(format!("{id}.png"));
        copy(&src, &prepared.join(to).join(format!("{id}.png")))?;
    }
    let lms = prepared.join("ori_imgs").join(format!("{id}.lms"));
    let own = truth.join("ori_imgs").join(format!("{id}.lms"));
    if own.is_file() {
        return copy(&own, &lms);
    }
    let labels = truth_labels(truth)?.join(format!("{id}.png"));
    let size = image::image_dimensions(&labels)
        .map_err(|e| Error::invalid(&labels, format!("not a readable image: {e}")))?;
    let regions = read_regions(&labels, size, Region::from_label_color)?;
    let marks = landmarks_from_regions(&regions, size.0)
        .ok_or_else(|| Error::invalid(&labels, "shows no head or no mouth"))?;
    std::fs::write(&lms, marks.to_text()).map_err(|e| Error::io(&lms, e))
}

fn copy(from: &Path, to: &Path) -> Result<()> {
    std::fs::copy(from, to).map_err(|e| Error::io(from, e))?;
    Ok(())
}

fn copy_dir(from: &Path, to: &Path) -> Result<()> {
    std::fs::create_dir_all(to).map_err(|e| Error::io(to, e))?;
    for entry in std::fs::read_dir(from).map_err(|e| Error::io(from, e))? {
        let path = entry.map_err(|e| Error::io(from, e))?.path();
        if path.is_file() {
            copy(&path, &to.join(path.file_name().unwrap_or_default()))?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;

    /// A camera at `distance` from `target` on the turned axis `turn * z`, looking at it.
    fn orbit(turn: DMat3, distance: f64, target: DVec3) -> CameraPose {
        CameraPose {
            rotation: turn,
            centre: target + turn * DVec3::new(0.0, 0.0, distance),
        }
    }

    /// A prepared track that turns 0.85 times as far as the truth, about a centre off the
    /// origin, `k` times as far away, in a rotated world: no similarity maps it onto the
    /// truth, but every prepared view sees the head's centre where the true view sees the
    /// origin. A view turned beyond the recording and moved away must then be carried about
    /// that centre: the carried camera looks straight at it from `k` times the true
    /// distance, as the true held-out camera looks at the origin.
    #[test]
    fn a_view_beyond_the_recording_turns_about_the_head_the_prepared_views_see() {
        let (k, centre) = (0.7, DVec3::new(0.05, -0.02, 0.1));
        let world = DMat3::from_axis_angle(DVec3::new(0.2, 1.0, -0.3).normalize(), 0.4);
        let turn = |yaw_deg: f64, pitch_deg: f64| {
            DMat3::from_rotation_y(yaw_deg.to_radians())
                * DMat3::from_rotation_x(pitch_deg.to_radians())
        };
        let (mut truth, mut track) = (BTreeMap::new(), BTreeMap::new());
        for id in 0..41i64 {
            let (yaw, pitch) = (id as f64 - 20.0, 8.0 * (id as f64 * 0.3).sin());
            truth.insert(id, orbit(turn(yaw, pitch), 1.0, DVec3::ZERO));
            track.insert(id, orbit(world * turn(0.85 * yaw, 0.85 * pitch), k, centre));
        }
        let truth = Track {
            poses: truth,
            focal: 500.0,
        };
        let track = Track {
            poses: track,
            focal: 500.0,
        };
        let ids: Vec<i64> = truth.poses.keys().copied().collect();
        let seen = seen_centre(&truth, &track, &ids, DVec3::ZERO);
        assert!((seen - centre).length() < 1e-4, "{seen}");
        let held_out = orbit(turn(30.0, -4.0), 1.15, DVec3::ZERO);
        let carried = from_nearest_frame(&truth, &track, &ids, seen, &held_out);
        let sees = carried.rotation.transpose() * (centre - carried.centre);
        let want = DVec3::new(0.0, 0.0, -k * 1.15);
        assert!((sees - want).length() < 1e-4, "{sees} against {want}");
    }
}
