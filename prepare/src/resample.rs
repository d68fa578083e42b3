//! A dataset analysed at one size, written out at a smaller one.
//!
//! Landmarks and feature tracks hold a pixel's worth of error at any size, so a head found
//! in a 512-pixel frame is posed four times more finely than in the same frame at 128. A
//! dataset wanted at 128 from a larger video is therefore prepared at the larger size and
//! then shrunk: its frames, heads, background and parsing are resized, its `.lms` points and
//! head boxes scaled, its intrinsics scaled. The camera poses do not change: they do not
//! depend on the pixel size.

use std::path::{Path, PathBuf};

use image::imageops::FilterType;
use nldf_core::dataset::{SCENE_FILE, Split, TransformsFile};
use nldf_core::image::Rect;
use nldf_core::landmarks::Landmarks;
use rayon::prelude::*;

use crate::error::{Error, Result};

/// Label images, resized by the nearest pixel so that no new label appears.
const LABEL_DIRS: [&str; 3] = ["parsing", "regions", "truth/regions"];
/// 16-bit depth maps (`nldf synth`), resized by the nearest pixel.
const DEPTH_DIR: &str = "depth";
/// Pictures, resized with a triangle filter.
const PHOTO_DIRS: [&str; 3] = ["ori_imgs", "head_imgs", "torso_imgs"];
/// Every split's transforms file that may be there.
const SPLITS: [Split; 5] = [
    Split::Train,
    Split::Val,
    Split::Novel,
    Split::Voice,
    Split::Sweep,
];

/// Shrinks the dataset at `dir`, written at `from x from` pixels, to `to x to` in place (see
/// the module docs): a prepared dataset, an AD-NeRF one or a synthetic scene (its held-out
/// splits, exact labels, depth maps and `scene.json` intrinsics too). Nothing happens when
/// `to` is not below `from`.
pub fn shrink_dataset(dir: &Path, from: u32, to: u32) -> Result<()> {
    if to >= from {
        return Ok(());
    }
    let r = to as f32 / from as f32;
    let present = |sub: &str| Some(dir.join(sub)).filter(|d| d.is_dir());
    let mut jobs: Vec<(PathBuf, Kind)> = Vec::new();
    for d in PHOTO_DIRS.iter().filter_map(|s| present(s)) {
        for ext in ["jpg", "png"] {
            jobs.extend(files_with(&d, ext)?.into_iter().map(|p| (p, Kind::Photo)));
        }
    }
    for d in LABEL_DIRS.iter().filter_map(|s| present(s)) {
        jobs.extend(files_with(&d, "png")?.into_iter().map(|p| (p, Kind::Label)));
    }
    if let Some(d) = present(DEPTH_DIR) {
        jobs.extend(files_with(&d, "png")?.into_iter().map(|p| (p, Kind::Depth)));
    }
    for bc in ["bc.jpg", "bc.png"] {
        let p = dir.join(bc);
        if p.is_file() {
            jobs.push((p, Kind::Photo));
        }
    }
    jobs.par_iter()
        .try_for_each(|(p, kind)| resize_file(p, to, *kind))?;
    if let Some(d) = present("ori_imgs") {
        for path in files_with(&d, "lms")? {
            let mut marks = Landmarks::load(&path)?;
            for p in &mut marks.points {
                *p = [p[0] * r, p[1] * r];
            }
            std::fs::write(&path, marks.to_text()).map_err(|e| Error::io(&path, e))?;
        }
    }
    for split in SPLITS {
        let path = dir.join(split.file_name());
        if !path.is_file() {
            continue;
        }
        let mut t = TransformsFile::load(&path)?;
        t.focal_len *= r;
        t.cx = to as f32 / 2.0;
        t.cy = to as f32 / 2.0;
        t.width = Some(to);
        t.height = Some(to);
        for f in &mut t.frames {
            f.face_rect = f.face_rect.map(|b| scaled_rect(b, r, to));
        }
        t.save(&path)?;
    }
    shrink_scene_file(&dir.join(SCENE_FILE), r, to)
}

/// `nldf synth`'s scene file, when there is one: its intrinsics and its size scaled.
fn shrink_scene_file(path: &Path, r: f32, to: u32) -> Result<()> {
    if !path.is_file() {
        return Ok(());
    }
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let mut scene: serde_json::Value = serde_json::from_str(&text)
        .map_err(|e| Error::invalid(path, format!("is not JSON: {e}")))?;
    let k = &mut scene["intrinsics"];
    let focal = k["focal"]
        .as_f64()
        .ok_or_else(|| Error::invalid(path, "has no intrinsics.focal"))?;
    k["focal"] = (focal * r as f64).into();
    k["cx"] = (to as f64 / 2.0).into();
    k["cy"] = (to as f64 / 2.0).into();
    k["width"] = to.into();
    k["height"] = to.into();
    if scene["config"]["size"].is_number() {
        scene["config"]["size"] = to.into();
    }
    nldf_core::files::write_json(path, &scene)?;
    Ok(())
}

/// How an image is resized.
#[derive(Debug, Clone, Copy)]
enum Kind {
    Photo,
    Label,
    Depth,
}

/// `rect` scaled by `r`, outward to whole pixels, kept inside a `size x size` frame.
fn scaled_rect(rect: Rect, r: f32, size: u32) -> Rect {
    let size = size as i64;
    let x0 = ((rect.x as f32 * r).floor() as i64).clamp(0, size);
    let y0 = ((rect.y as f32 * r).floor() as i64).clamp(0, size);
    let x1 = (((rect.x + rect.w) as f32 * r).ceil() as i64).clamp(x0, size);
    let y1 = (((rect.y + rect.h) as f32 * r).ceil() as i64).clamp(y0, size);
    Rect {
        x: x0,
        y: y0,
        w: x1 - x0,
        h: y1 - y0,
    }
}

/// The files of `dir` ending in `.ext`, in name order.
fn files_with(dir: &Path, ext: &str) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))? {
        let path = entry.map_err(|e| Error::io(dir, e))?.path();
        if path.extension().is_some_and(|e| e == ext) {
            out.push(path);
        }
    }
    out.sort();
    Ok(out)
}

/// Rewrites the image at `path` resized to `size x size` as `kind` says (its format kept:
/// JPEG at the job's quality, PNG otherwise).
fn resize_file(path: &Path, size: u32, kind: Kind) -> Result<()> {
    let img = image::open(path).map_err(|e| Error::invalid(path, format!("cannot read: {e}")))?;
    let written = match kind {
        Kind::Depth => {
            image::imageops::resize(&img.to_luma16(), size, size, FilterType::Nearest).save(path)
        }
        Kind::Label | Kind::Photo => {
            let filter = match kind {
                Kind::Label => FilterType::Nearest,
                _ => FilterType::Triangle,
            };
            let small = image::imageops::resize(&img.to_rgb8(), size, size, filter);
            if path.extension().is_some_and(|e| e == "jpg") {
                return crate::frames::save_jpeg(path, small.as_raw(), size);
            }
            small.save(path)
        }
    };
    written.map_err(|e| Error::invalid(path, format!("cannot write: {e}")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn head_boxes_scale_outward_and_stay_inside() {
        let b = scaled_rect(
            Rect {
                x: 101,
                y: 50,
                w: 203,
                h: 460,
            },
            0.25,
            128,
        );
        assert_eq!((b.x, b.y), (25, 12));
        // 304 / 4 = 76 exactly; 510 / 4 = 127.5, up to 128.
        assert_eq!((b.x + b.w, b.y + b.h), (76, 128));
        let edge = scaled_rect(
            Rect {
                x: 500,
                y: 0,
                w: 40,
                h: 4,
            },
            0.25,
            128,
        );
        assert_eq!((edge.x, edge.w), (125, 3));
    }
}
