//! The teacher's per-segment colours (Eq. 5) that the student distils: rendered once per hit
//! pixel of every view and cached in `targets.safetensors` beside the student's checkpoint,
//! with the teacher's step and a fingerprint of the views, so that a cache made for other
//! views or another teacher is never used.

use std::collections::HashMap;
use std::path::Path;

use candle_core::{Device, Tensor};
use nldf_core::beam::{BeamAnchor, beam_ray};
use nldf_core::rays::Rays;

use crate::error::Result;
use crate::trainers::checkpoint::{load_tensors, save_tensors};
use crate::trainers::data::TrainData;
use crate::trainers::teacher_trainer::TeacherModel;
use crate::trainers::views::{FrameBeams, View};

/// What the teacher renders per ray for the student: `segments` Eq. 5 colours and the
/// accumulated weight after them (see `Teacher::segment_targets`), along
/// each ray anchored as the student's beams are (`anchor`), so that the teacher's
/// `[near, far]` window sits where the student's beam points do, however close the camera.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TargetLayout {
    pub segments: usize,
    pub anchor: Option<BeamAnchor>,
}

impl TargetLayout {
    /// Values per ray: `3 m` colours and the opacity.
    pub fn width(&self) -> usize {
        3 * self.segments + 1
    }
}

/// The teacher's targets of every hit pixel of every view (`[n_pixels, layout.width()]`
/// flat per view). `progress(done, total)` is called per view.
pub fn teacher_targets(
    teacher: &TeacherModel,
    data: &TrainData,
    views: &[View],
    beams: &[FrameBeams],
    layout: TargetLayout,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<Vec<Vec<f32>>> {
    let mut out = Vec::with_capacity(views.len());
    for (vi, (view, fb)) in views.iter().zip(beams).enumerate() {
        out.push(view_targets(teacher, data, view, fb, layout)?);
        progress(vi + 1, views.len());
    }
    Ok(out)
}

/// The teacher's targets of one view's hit pixels, with the view's recorded audio code
/// (`[fb.pixels.len(), layout.width()]` flat).
pub fn view_targets(
    teacher: &TeacherModel,
    data: &TrainData,
    view: &View,
    fb: &FrameBeams,
    layout: TargetLayout,
) -> Result<Vec<f32>> {
    let mut rays = Rays::with_capacity(fb.pixels.len());
    for &(i, j) in &fb.pixels {
        let (o, d) = view.camera.ray(i as f32, j as f32);
        let (o, d) = beam_ray(layout.anchor.as_ref(), o, d);
        rays.push(o, d);
    }
    if rays.is_empty() {
        return Ok(Vec::new());
    }
    let code = teacher.audio_codes(data, &[view.aud_id])?;
    Ok(teacher
        .teacher
        .segment_targets(&rays, &code, &data.head_range(), layout.segments)?)
}

/// Writes the targets with the teacher's step and the views' fingerprint.
pub fn save_targets(
    path: &Path,
    targets: &[Vec<f32>],
    layout: TargetLayout,
    teacher_step: usize,
    views: &str,
) -> Result<()> {
    let mut tensors = HashMap::new();
    let width = layout.width();
    for (f, t) in targets.iter().enumerate() {
        let rows = t.len() / width;
        tensors.insert(
            format!("frame.{f}"),
            Tensor::from_slice(t, (rows, width), &Device::Cpu)?,
        );
    }
    let meta = [
        ("teacher_step".to_string(), teacher_step.to_string()),
        ("segments".to_string(), layout.segments.to_string()),
        // Caches from before every student had opacity said `false`.
        ("opacity".to_string(), "true".to_string()),
        ("frames".to_string(), targets.len().to_string()),
        ("views".to_string(), views.to_string()),
    ]
    .into_iter()
    .collect();
    save_tensors(path, &tensors, meta)
}

/// The cached targets when they fit the views, `m` and (when known) the teacher's step.
pub fn load_targets(
    path: &Path,
    beams: &[FrameBeams],
    layout: TargetLayout,
    teacher_step: Option<usize>,
    views: &str,
) -> Result<Option<Vec<Vec<f32>>>> {
    let (tensors, meta) = load_tensors(path)?;
    let get = |k: &str| meta.get(k).and_then(|v| v.parse::<usize>().ok());
    let fits = get("segments") == Some(layout.segments)
        && meta.get("opacity").map(String::as_str) == Some("true")
        && get("frames") == Some(beams.len())
        && meta.get("views").map(String::as_str) == Some(views)
        && teacher_step.is_none_or(|s| get("teacher_step") == Some(s));
    if !fits {
        return Ok(None);
    }
    let mut out = Vec::with_capacity(beams.len());
    for (f, fb) in beams.iter().enumerate() {
        let Some(t) = tensors.get(&format!("frame.{f}")) else {
            return Ok(None);
        };
        if t.dims() != [fb.pixels.len(), layout.width()] {
            return Ok(None);
        }
        out.push(t.flatten_all()?.to_vec1()?);
    }
    Ok(Some(out))
}
