//! Drawing a student's batches: main beams from the views' hit pixels, pool beams from
//! the pool.

use rand::Rng;
use rand::seq::index::sample as sample_indices;
use rand_chacha::ChaCha8Rng;

use super::StudentRun;

/// One beam of a batch: training frame and hit-pixel index.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct BeamRef {
    pub(super) frame: u32,
    pub(super) pixel: u32,
}
impl StudentRun {
    /// Draws the main batch: per picked frame, rays from the mouth, the face and the rest
    /// of the hit pixels in the configured proportions.
    pub(super) fn draw_batch(&self, rng: &mut ChaCha8Rng) -> Vec<BeamRef> {
        let t = &self.model.cfg.train;
        let usable = |recorded: bool| -> Vec<usize> {
            (0..self.beams.len())
                .filter(|&f| {
                    self.views[f].recorded == recorded
                        && !self.beams[f].pixels.is_empty()
                        && (recorded || self.targets.get(f).is_some_and(|t| !t.is_empty()))
                })
                .collect()
        };
        let (real, pseudo) = (usable(true), usable(false));
        if real.is_empty() {
            return Vec::new();
        }
        let n_frames = t.frames_per_batch.max(1);
        let n_pseudo = if pseudo.is_empty() {
            0
        } else {
            ((t.pseudo_fraction.clamp(0.0, 1.0) * n_frames as f32).round() as usize)
                .min(n_frames - 1)
                .min(pseudo.len())
        };
        let n_real = (n_frames - n_pseudo).min(real.len());
        let n_frames = n_real + n_pseudo;
        let mut chosen: Vec<usize> = sample_indices(rng, real.len(), n_real)
            .into_iter()
            .map(|u| real[u])
            .collect();
        chosen.extend(
            sample_indices(rng, pseudo.len(), n_pseudo)
                .into_iter()
                .map(|u| pseudo[u]),
        );
        let mut batch = Vec::with_capacity(t.batch_rays);
        for (slot, &fi) in chosen.iter().enumerate() {
            let fb = &self.beams[fi];
            let count = t.batch_rays / n_frames + usize::from(slot < t.batch_rays % n_frames);
            let n_mouth = if fb.mouth.is_empty() {
                0
            } else {
                (t.mouth_fraction.clamp(0.0, 1.0) * count as f32).round() as usize
            };
            let n_face = if fb.face.is_empty() {
                0
            } else {
                ((t.face_fraction.clamp(0.0, 1.0) * count as f32).round() as usize)
                    .saturating_sub(n_mouth)
            };
            let n_mouth = n_mouth.min(count);
            let n_face = n_face.min(count - n_mouth);
            let n_rest = count - n_mouth - n_face;
            // `face` and `other` split a non-empty frame's pixels, so one of them has some.
            let rest = if fb.other.is_empty() {
                &fb.face
            } else {
                &fb.other
            };
            for (list, n) in [(&fb.mouth, n_mouth), (&fb.face, n_face), (rest, n_rest)] {
                for _ in 0..n {
                    batch.push(BeamRef {
                        frame: fi as u32,
                        pixel: list[rng.random_range(0..list.len())],
                    });
                }
            }
        }
        batch
    }
    /// The beams of the pool entries `drawn`.
    pub(super) fn pool_refs(&self, drawn: &[usize]) -> Vec<BeamRef> {
        drawn
            .iter()
            .map(|&i| BeamRef {
                frame: self.pool.entries[i].frame,
                pixel: self.pool.entries[i].pixel,
            })
            .collect()
    }
}
