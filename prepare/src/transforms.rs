//! The prepared dataset's transforms files: each kept frame's camera and head box, split as
//! AD-NeRF splits, with AD-NeRF's ray bounds.

use std::path::Path;

use nldf_core::camera::Intrinsics;
use nldf_core::dataset::{FrameEntry, TransformsFile};
use nldf_core::image::Rect;

use crate::error::Result;

/// AD-NeRF's split: the first 10/11 of the frames train, the rest are held out (`val`).
const TRAIN_SHARE: f64 = 10.0 / 11.0;

/// Writes `transforms_train.json` and `transforms_val.json` for the kept frames (their
/// cameras `c2w` and head boxes `rects`), split as AD-NeRF splits; returns the training
/// frames' count.
pub(crate) fn write_transforms(
    dir: &Path,
    kept: &[usize],
    c2w: &[glam::Mat4],
    rects: &[Option<[u32; 4]>],
    k: &Intrinsics,
    fps: f64,
) -> Result<usize> {
    let entries: Vec<FrameEntry> = kept
        .iter()
        .zip(c2w)
        .zip(rects)
        .map(|((&i, c2w), rect)| FrameEntry {
            img_id: i as i64,
            aud_id: i as i64,
            transform_matrix: c2w.transpose().to_cols_array_2d(),
            face_rect: rect.map(|[x, y, w, h]| Rect {
                x: x as i64,
                y: y as i64,
                w: w as i64,
                h: h as i64,
            }),
            eye: None,
        })
        .collect();
    let n_train =
        ((entries.len() as f64 * TRAIN_SHARE).round() as usize).clamp(1, entries.len() - 1);
    let (near, far) = bounds(c2w);
    for (name, part) in [
        ("transforms_train.json", &entries[..n_train]),
        ("transforms_val.json", &entries[n_train..]),
    ] {
        let file = TransformsFile {
            focal_len: k.focal,
            cx: k.cx,
            cy: k.cy,
            near: Some(near),
            far: Some(far),
            fps: Some(fps as f32),
            width: Some(k.width),
            height: Some(k.height),
            frames: part.to_vec(),
        };
        file.save(&dir.join(name))?;
    }
    Ok(n_train)
}

/// AD-NeRF's bounds about the mean camera depth of the head's origin, in metres: the head
/// reaches 0.2 in front of the origin, and 0.4 behind it is empty.
fn bounds(c2w: &[glam::Mat4]) -> (f32, f32) {
    let mean = c2w
        .iter()
        .map(|m| m.z_axis.truncate().dot(m.w_axis.truncate()))
        .sum::<f32>()
        / c2w.len().max(1) as f32;
    ((mean - 0.2).max(1e-3), mean + 0.4)
}
