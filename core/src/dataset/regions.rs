//! A dataset's region maps: a frame's regions read from nldf's labels or AD-NeRF's parsing
//! (with the landmarks' mouth), and region maps written as PNGs.

use std::path::Path;

use super::load::Dataset;
use super::validate::Frame;
use crate::error::Result;
use crate::image::{ImageRgb, save_png_bytes};
use crate::landmarks::Landmarks;
use crate::region::{MouthSource, Region};

impl Dataset {
    /// A frame's regions (`None` when the dataset has neither `regions/` nor `parsing/`):
    /// nldf's labels when present; otherwise AD-NeRF's parsing (head, neck, torso) with the
    /// mouth where the head lies inside the landmarks' outer lip contour when the frame has
    /// landmarks.
    pub fn load_regions(&self, frame: &Frame) -> Result<Option<Vec<Region>>> {
        let decode = |path: &Path, read: fn([u8; 3]) -> Region| -> Result<Vec<Region>> {
            let img = ImageRgb::load(path)?;
            self.check_size(path, img.width, img.height)?;
            Ok(img
                .to_rgb8()
                .chunks_exact(3)
                .map(|c| read([c[0], c[1], c[2]]))
                .collect())
        };
        if let Some(path) = &frame.labels_path {
            return Ok(Some(decode(path, Region::from_label_color)?));
        }
        let Some(path) = &frame.parsing_path else {
            return Ok(None);
        };
        let mut regions = decode(path, Region::from_parsing_color)?;
        if let Some(lms) = &frame.landmarks_path {
            let k = &self.intrinsics;
            let mouth = Landmarks::load(lms)?.mouth_mask(k.width, k.height);
            for (r, m) in regions.iter_mut().zip(mouth) {
                if m && *r == Region::Face {
                    *r = Region::Mouth;
                }
            }
        }
        Ok(Some(regions))
    }

    /// Where the frames' mouth region comes from: nldf's labels, AD-NeRF's landmarks (with
    /// its parsing), or nowhere.
    pub fn mouth_source(&self) -> MouthSource {
        let first = self.train.first().or(self.val.first());
        match first {
            Some(f) if f.labels_path.is_some() => MouthSource::Labels,
            Some(f) if f.parsing_path.is_some() && f.landmarks_path.is_some() => {
                MouthSource::Landmarks
            }
            _ => MouthSource::Unknown,
        }
    }
}

/// Writes `regions` (row-major) as a PNG of `color`s ([`Region::parsing_color`] for
/// AD-NeRF's `parsing/`, [`Region::label_color`] for nldf's `regions/`), atomically.
pub fn save_regions_png(
    path: &Path,
    width: u32,
    height: u32,
    regions: &[Region],
    color: fn(Region) -> [u8; 3],
) -> Result<()> {
    let bytes: Vec<u8> = regions.iter().flat_map(|r| color(*r)).collect();
    save_png_bytes(path, width, height, image::ExtendedColorType::Rgb8, &bytes)
}
