//! The upsampler's training crops: the coarse boxes of the recorded views, crops the
//! teacher renders of pseudo views, and each step's batch drawn from both.

use candle_core::{Device, Tensor};
use nldf_core::bounds::HeadRange;
use nldf_core::rays::rays_for_pixels;
use rand::Rng;
use rand_chacha::ChaCha8Rng;

use super::config::UpsamplerTrainConfig;
use crate::error::Result;
use crate::networks::upsampler::{CoarseBox, coarse_box_features, image_box};
use crate::trainers::data::TrainData;
use crate::trainers::student_trainer::StudentModel;
use crate::trainers::teacher_trainer::TeacherModel;
use crate::trainers::views::{View, training_views};

/// One training crop: the coarse input `[C, s, s]` (`s = crop + 2 halo`) and, for the
/// central `crop r` pixels on a side, the target and the background, `[3, crop r, crop r]`.
#[derive(Clone)]
pub(super) struct Crop {
    pub(super) grid: Tensor,
    pub(super) target: Tensor,
    pub(super) background: Tensor,
}

/// A recorded view's coarse box and its frame, from which crops are cut at each step.
pub(super) struct RecordedView {
    coarse: CoarseBox,
    image: usize,
}

/// One step's batch of crops: the pseudo views' share (`pseudo_fraction`, when there
/// are any) drawn from `pseudo`, the rest cut from random recorded views.
pub(super) fn draw_crops(
    recorded: &[RecordedView],
    pseudo: &[Crop],
    data: &TrainData,
    rng: &mut ChaCha8Rng,
    t: &UpsamplerTrainConfig,
    r: usize,
) -> Result<Vec<Crop>> {
    let n_pseudo_step = if pseudo.is_empty() {
        0
    } else {
        ((t.batch as f64 * t.pseudo_fraction).round() as usize).min(t.batch)
    };
    let mut crops = Vec::with_capacity(t.batch);
    for b in 0..t.batch {
        if b < n_pseudo_step {
            crops.push(pseudo[rng.random_range(0..pseudo.len())].clone());
        } else {
            let v = &recorded[rng.random_range(0..recorded.len())];
            let mouth = rng.random::<f64>() < t.mouth_fraction;
            crops.push(recorded_crop(v, data, rng, mouth, t, r)?);
        }
    }
    Ok(crops)
}

/// What cutting the training crops reads: the data, the fixed student and the crops'
/// geometry.
pub(super) struct CropCutter<'a> {
    pub(super) data: &'a TrainData,
    pub(super) student: &'a StudentModel,
    pub(super) t: &'a UpsamplerTrainConfig,
    /// The upsampler's factor.
    pub(super) r: usize,
    /// Coarse rays on a crop's side, halo included.
    pub(super) side: usize,
    /// Coarse rays around the hits in a coarse box.
    pub(super) margin: usize,
    pub(super) range: HeadRange,
}

impl CropCutter<'_> {
    /// The recorded views' coarse boxes, then the crops the teacher renders once of the
    /// pseudo views.
    pub(super) fn prepare(
        &self,
        teacher: &TeacherModel,
        rng: &mut ChaCha8Rng,
    ) -> Result<(Vec<RecordedView>, Vec<Crop>)> {
        let student = self.student;
        // Recorded views: the coarse box of every training frame.
        let views = training_views(self.data, &student.cfg.train);
        let mut recorded = Vec::new();
        for (vi, view) in views.iter().filter(|v| v.recorded).enumerate() {
            if let Some(coarse) = self.coarse_of(view)? {
                recorded.push(RecordedView { coarse, image: vi });
            }
        }
        // Pseudo views: crops the teacher renders once.
        let mut pseudo = Vec::new();
        let pseudo_views: Vec<_> = views.iter().filter(|v| !v.recorded).collect();
        let n_pseudo = self.t.pseudo_views.min(pseudo_views.len());
        for k in 0..n_pseudo {
            let view = pseudo_views[k * pseudo_views.len() / n_pseudo.max(1)];
            let Some(coarse) = self.coarse_of(view)? else {
                continue;
            };
            self.pseudo_crops(teacher, view, &coarse, rng, &mut pseudo)?;
        }
        Ok((recorded, pseudo))
    }

    /// A view's coarse box, when it holds a hit and a whole crop.
    fn coarse_of(&self, view: &View) -> Result<Option<CoarseBox>> {
        let (student, side) = (self.student, self.side);
        let code = student.audio_codes(self.data, &[view.aud_id])?;
        let coarse = coarse_box_features(
            &student.student,
            &view.camera,
            &code,
            &self.range,
            (self.r, self.margin),
        )?;
        let (bh, bw) = (coarse.rows.1 - coarse.rows.0, coarse.cols.1 - coarse.cols.0);
        Ok((coarse.any_hit && bh >= side && bw >= side).then_some(coarse))
    }

    /// Cuts `pseudo_crops` random crops of a pseudo view's coarse box into `crops`, their
    /// targets rendered by the teacher.
    fn pseudo_crops(
        &self,
        teacher: &TeacherModel,
        view: &View,
        coarse: &CoarseBox,
        rng: &mut ChaCha8Rng,
        crops: &mut Vec<Crop>,
    ) -> Result<()> {
        let (t, r, side) = (self.t, self.r, self.side);
        let ds = &self.data.dataset;
        let (bh, bw) = (coarse.rows.1 - coarse.rows.0, coarse.cols.1 - coarse.cols.0);
        let teacher_code = teacher.audio_codes(self.data, &[view.aud_id])?;
        for _ in 0..t.pseudo_crops {
            let (y, x) = (
                rng.random_range(0..=bh - side),
                rng.random_range(0..=bw - side),
            );
            let grid = coarse
                .grid
                .narrow(2, y, side)?
                .narrow(3, x, side)?
                .squeeze(0)?;
            // The central rays' blocks in output pixels.
            let row0 = (coarse.rows.0 + y + t.halo) * r;
            let col0 = (coarse.cols.0 + x + t.halo) * r;
            let n = t.crop * r;
            let pixels: Vec<(u32, u32)> = (0..n * n)
                .map(|p| ((col0 + p % n) as u32, (row0 + p / n) as u32))
                .collect();
            let bg: Vec<f32> = pixels
                .iter()
                .flat_map(|&(i, j)| ds.background.get(i, j))
                .collect();
            let rays = rays_for_pixels(&view.camera, &pixels);
            let colours = teacher.teacher.render_eval(
                &rays,
                &bg,
                &teacher_code,
                &self.range,
                teacher.teacher.cfg.min_transmittance,
            )?;
            let planar = |v: &[f32]| -> Result<Tensor> {
                Ok(Tensor::from_vec(v.to_vec(), (n, n, 3), &Device::Cpu)?
                    .permute((2, 0, 1))?
                    .contiguous()?)
            };
            crops.push(Crop {
                grid,
                target: planar(&colours)?,
                background: planar(&bg)?,
            });
        }
        Ok(())
    }
}

/// A random crop of a recorded view, its target from the frame itself; with `mouth`, one
/// whose loss-counted centre holds a random pixel of the frame's mouth region (when it has
/// one).
fn recorded_crop(
    v: &RecordedView,
    data: &TrainData,
    rng: &mut ChaCha8Rng,
    mouth: bool,
    t: &UpsamplerTrainConfig,
    r: usize,
) -> Result<Crop> {
    let (halo, crop) = (t.halo, t.crop);
    let side = crop + 2 * halo;
    let c = &v.coarse;
    let (bh, bw) = (c.rows.1 - c.rows.0, c.cols.1 - c.cols.0);
    let mouth_pixels = &data.mouth_pixels[v.image];
    let (y, x) = if mouth && !mouth_pixels.is_empty() {
        let (i, j) = mouth_pixels[rng.random_range(0..mouth_pixels.len())];
        // The crop's top-left so that coarse ray (i / r, j / r) falls in its centre.
        let mut place = |at: usize, lo: usize, n: usize| -> usize {
            let shift = rng.random_range(0..crop);
            at.saturating_sub(lo + halo + shift).min(n - side)
        };
        let y = place(j as usize / r, c.rows.0, bh);
        let x = place(i as usize / r, c.cols.0, bw);
        (y, x)
    } else {
        (
            rng.random_range(0..=bh - side),
            rng.random_range(0..=bw - side),
        )
    };
    let grid = c.grid.narrow(2, y, side)?.narrow(3, x, side)?.squeeze(0)?;
    let row0 = (c.rows.0 + y + halo) * r;
    let col0 = (c.cols.0 + x + halo) * r;
    let n = crop * r;
    let rows = (row0, row0 + n);
    let cols = (col0, col0 + n);
    Ok(Crop {
        grid,
        target: image_box(&data.images[v.image], rows, cols)?.squeeze(0)?,
        background: image_box(&data.dataset.background, rows, cols)?.squeeze(0)?,
    })
}
