//! A dataset prepared for training: the dataset with the audio features a run reads,
//! the decoded training frames, their mouth pixels and the head's bounds.

use std::path::Path;

use nldf_core::bounds::{Bounds, dataset_bounds};
use nldf_core::dataset::{AudioChoice, Dataset, Split};
use nldf_core::image::ImageRgb;
use nldf_core::region::Region;

use crate::error::Result;

/// A dataset prepared for training: decoded training frames and the head's bounds.
#[derive(Debug, Clone)]
pub struct TrainData {
    pub dataset: Dataset,
    /// Decoded images of the training frames, in split order.
    pub images: Vec<ImageRgb>,
    /// Per training frame, its mouth pixels (`i`, `j`) from the parsing masks (empty
    /// without masks or when not decoded).
    pub mouth_pixels: Vec<Vec<(u32, u32)>>,
    pub bounds: Bounds,
}

impl TrainData {
    /// The audio neighbourhoods of the frames `aud_ids`, the audio encoder's input (see
    /// [`crate::networks::audio_net::neighbourhoods`]).
    ///
    /// # Shapes
    /// - returns `[aud_ids.len(), att_frames, window, n_features]`
    pub fn neighbourhoods(
        &self,
        aud_ids: &[usize],
        att_frames: usize,
    ) -> Result<candle_core::Tensor> {
        Ok(crate::networks::audio_net::neighbourhoods(
            &self.dataset.audio,
            aud_ids,
            att_frames,
        )?)
    }

    /// Where the scene's rays are sampled: the head's bounds within the dataset's
    /// `[near, far]`.
    pub fn head_range(&self) -> nldf_core::bounds::HeadRange {
        nldf_core::bounds::HeadRange {
            bounds: self.bounds,
            near: self.dataset.near,
            far: self.dataset.far,
        }
    }

    /// Loads and validates a dataset and decodes its training frames.
    pub fn load(root: &Path) -> Result<TrainData> {
        Self::open(root, true)
    }

    /// Loads and validates a dataset; decodes the training frames only with `decode`
    /// (rendering and evaluation need none).
    pub fn open(root: &Path, decode: bool) -> Result<TrainData> {
        Self::open_with(root, decode, &AudioChoice::Auto)
    }

    /// [`TrainData::open`] with the audio features `audio` says (a trained run's, say).
    pub fn open_with(root: &Path, decode: bool, audio: &AudioChoice) -> Result<TrainData> {
        Self::open_held_out(root, decode, audio, Split::Val)
    }

    /// [`TrainData::open_with`] with `held_out`'s frames (and, for `voice`, its audio) as
    /// the held-out ones (see [`Dataset::load_held_out`]).
    pub fn open_held_out(
        root: &Path,
        decode: bool,
        audio: &AudioChoice,
        held_out: Split,
    ) -> Result<TrainData> {
        let dataset = Dataset::load_held_out(root, audio, held_out)?;
        let (mut images, mut mouth_pixels) = (Vec::new(), Vec::new());
        if decode {
            let width = dataset.intrinsics.width as usize;
            for f in dataset.frames(Split::Train) {
                images.push(dataset.load_image(f)?);
                let mouth = match dataset.load_regions(f)? {
                    Some(regions) => regions
                        .iter()
                        .enumerate()
                        .filter(|(_, r)| **r == Region::Mouth)
                        .map(|(p, _)| ((p % width) as u32, (p / width) as u32))
                        .collect(),
                    None => Vec::new(),
                };
                mouth_pixels.push(mouth);
            }
        }
        let bounds = dataset_bounds(&dataset)?;
        Ok(TrainData {
            dataset,
            images,
            mouth_pixels,
            bounds,
        })
    }
}
