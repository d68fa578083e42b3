//! The views the student learns from: the recorded training frames and, with R2L's pseudo
//! data, the teacher's views at poses around them; each view's hit pixels split into face,
//! mouth and the rest; the audio code of each view.

use candle_core::Tensor;
use nldf_core::camera::{Camera, turn_about};
use nldf_core::dataset::Split;
use nldf_core::rays::head_rays;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::config::StudentTrainConfig;
use crate::data::TrainData;
use crate::error::Result;

/// The pixels of one training frame whose rays hit the head's bounds (the only ones the
/// student sees), split by where they lie.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameBeams {
    /// `(i, j)` of every hit pixel, in row-major order.
    pub pixels: Vec<(u32, u32)>,
    /// Indices into `pixels`: inside `face_rect`, outside it, inside the mouth region.
    pub face: Vec<u32>,
    pub other: Vec<u32>,
    pub mouth: Vec<u32>,
}

/// A view the student learns from: a training frame, or a pseudo view (R2L's pseudo data)
/// whose pose and audio lie between the training frames'.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    pub camera: Camera,
    /// Audio ids whose codes are mixed: `weight code(a) + (1 - weight) code(b)`.
    pub audio: (usize, usize),
    pub weight: f32,
    /// The training frame the view comes from (its face and mouth regions are used).
    pub source: usize,
    /// Whether the view is a training frame, with a ground-truth image.
    pub recorded: bool,
}

/// The training frames as views, then `cfg.pseudo_frames` pseudo views (with distillation
/// on): each a seeded training frame's camera turned about the head's centre by up to
/// `pseudo_yaw_deg` and `pseudo_pitch_deg`, with the audio codes of two seeded training
/// frames mixed by a uniform weight.
pub fn training_views(data: &TrainData, cfg: &StudentTrainConfig) -> Vec<View> {
    let ds = &data.dataset;
    let frames = ds.frames(Split::Train);
    let mut views: Vec<View> = frames
        .iter()
        .enumerate()
        .map(|(fi, f)| View {
            camera: ds.camera(f),
            audio: (f.aud_id, f.aud_id),
            weight: 1.0,
            source: fi,
            recorded: true,
        })
        .collect();
    if !cfg.distill || frames.is_empty() {
        return views;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x5eed_5eed);
    let centre = 0.5 * (data.bounds.lo + data.bounds.hi);
    for _ in 0..cfg.pseudo_frames {
        let source = rng.random_range(0..frames.len());
        let other = rng.random_range(0..frames.len());
        let weight: f32 = rng.random_range(0.0..=1.0);
        let yaw = cfg.pseudo_yaw_deg.to_radians() * rng.random_range(-1.0f32..=1.0);
        let pitch = cfg.pseudo_pitch_deg.to_radians() * rng.random_range(-1.0f32..=1.0);
        let base = ds.camera(&frames[source]);
        views.push(View {
            camera: Camera {
                intrinsics: base.intrinsics,
                c2w: turn_about(centre, yaw, pitch) * base.c2w,
            },
            audio: (frames[source].aud_id, frames[other].aud_id),
            weight,
            source,
            recorded: false,
        });
    }
    views
}

/// The hit pixels of every view; a view's face and mouth regions are its source frame's.
pub fn frame_beams(data: &TrainData, views: &[View]) -> Vec<FrameBeams> {
    let ds = &data.dataset;
    let frames = ds.frames(Split::Train);
    let width = ds.intrinsics.width;
    views
        .par_iter()
        .map(|view| {
            let frame = &frames[view.source];
            let mouth: std::collections::HashSet<(u32, u32)> = data
                .mouth_pixels
                .get(view.source)
                .map(|m| m.iter().copied().collect())
                .unwrap_or_default();
            let head = head_rays(&view.camera, &data.head_range());
            let mut fb = FrameBeams::default();
            for r in 0..head.pixels.len() {
                let (i, j) = head.pixel_ij(r, width);
                let k = fb.pixels.len() as u32;
                fb.pixels.push((i, j));
                if frame.face_rect.contains(i, j) {
                    fb.face.push(k);
                } else {
                    fb.other.push(k);
                }
                if mouth.contains(&(i, j)) {
                    fb.mouth.push(k);
                }
            }
            fb
        })
        .collect()
}

/// The audio codes of `views`: `weight code(a) + (1 - weight) code(b)` row by row, with
/// `codes(ids)` the encoder's codes of audio ids (`[ids.len(), dim]`). Recorded frames
/// (weight 1) need only their own code, so the second encoder call is made only for
/// batches holding a pseudo view.
///
/// # Shapes
/// - returns `[views.len(), dim]`
pub fn codes_of_views(
    views: &[&View],
    codes: impl Fn(&[usize]) -> Result<Tensor>,
) -> Result<Tensor> {
    let a: Vec<usize> = views.iter().map(|v| v.audio.0).collect();
    let codes_a = codes(&a)?;
    if views.iter().all(|v| v.weight == 1.0) {
        return Ok(codes_a);
    }
    let b: Vec<usize> = views.iter().map(|v| v.audio.1).collect();
    let n = views.len();
    let dev = codes_a.device().clone();
    let w = Tensor::from_vec(views.iter().map(|v| v.weight).collect(), (n, 1), &dev)?;
    let rest = Tensor::from_vec(views.iter().map(|v| 1.0 - v.weight).collect(), (n, 1), &dev)?;
    Ok((codes_a.broadcast_mul(&w)? + codes(&b)?.broadcast_mul(&rest)?)?)
}

/// A fingerprint of the views (poses, audio and mixing weights), stored with the cached
/// targets so that a cache made for other views is never used (FNV-1a over their bits).
pub fn views_fingerprint(views: &[View]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |v: u64| {
        for b in v.to_le_bytes() {
            h = (h ^ b as u64).wrapping_mul(0x0100_0000_01b3);
        }
    };
    for v in views {
        v.camera
            .c2w
            .to_cols_array()
            .iter()
            .for_each(|x| eat(x.to_bits() as u64));
        eat(v.audio.0 as u64);
        eat(v.audio.1 as u64);
        eat(v.weight.to_bits() as u64);
    }
    format!("{h:016x}")
}
