//! Region labels of a frame: which pixels are background, the head (face, mouth, eyes), the
//! neck or the torso. Used for face-biased ray batches, mouth rays, the head's visual hull and
//! region metrics (head-region and mouth PSNR).
//!
//! Two files carry labels, each in its own convention:
//! - `parsing/<img_id>.png`, AD-NeRF's face parsing as AD-NeRF writes it. AD-NeRF builds its
//!   label image in OpenCV's BGR order and writes it with `cv2.imwrite`, so read from disk as
//!   RGB its head is blue `(0, 0, 255)`, its neck green, its torso (cloth) red and its
//!   background white ([`Region::parsing_color`]). It has no mouth label.
//! - `regions/<img_id>.png`, nldf's own exact labels of the head's parts (`nldf synth` writes
//!   them), in a palette of its own ([`Region::label_color`]) so the two files cannot be
//!   mistaken for each other.
//!
//! Without `regions/`, the mouth comes from AD-NeRF's 68 landmarks ([`crate::landmarks`]).

/// One pixel's region.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Region {
    Background = 0,
    /// The head outside the mouth and the eyes (or the whole head where those are unknown).
    Face = 1,
    Mouth = 2,
    Eyes = 3,
    Neck = 4,
    /// The torso and its cloth.
    Torso = 5,
}

/// Which of a dataset's files a frame's mouth region comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MouthSource {
    /// nldf's own labels (`regions/`).
    Labels,
    /// AD-NeRF's landmarks (`<id>.lms`, the lips' outline, points 48-59).
    Landmarks,
    /// No mouth region is known: mouth rays and mouth scores are off.
    Unknown,
}

impl MouthSource {
    /// What the source is, for messages.
    pub fn describe(self) -> &'static str {
        match self {
            MouthSource::Labels => "nldf's region labels (regions/)",
            MouthSource::Landmarks => "the 68 landmarks' lips (points 48-59 of <id>.lms)",
            MouthSource::Unknown => {
                "unknown: no regions/ labels and no <id>.lms landmarks, so no mouth rays and no mouth PSNR"
            }
        }
    }
}

impl Region {
    /// All regions, in label order.
    pub const ALL: [Region; 6] = [
        Region::Background,
        Region::Face,
        Region::Mouth,
        Region::Eyes,
        Region::Neck,
        Region::Torso,
    ];

    /// The colour of this region in AD-NeRF's `parsing/` PNGs as read from disk (RGB): the
    /// whole head blue, the neck green, the torso red, the background white.
    pub fn parsing_color(self) -> [u8; 3] {
        match self {
            Region::Background => [255, 255, 255],
            Region::Face | Region::Mouth | Region::Eyes => [0, 0, 255],
            Region::Neck => [0, 255, 0],
            Region::Torso => [255, 0, 0],
        }
    }

    /// The region of an AD-NeRF `parsing/` pixel: the nearest of its four colours (parsing
    /// images may be JPEG-damaged). The head reads as [`Region::Face`].
    pub fn from_parsing_color(rgb: [u8; 3]) -> Region {
        nearest(
            &[
                Region::Background,
                Region::Face,
                Region::Neck,
                Region::Torso,
            ],
            rgb,
            Region::parsing_color,
        )
    }

    /// The colour of this region in nldf's own `regions/` PNGs.
    pub fn label_color(self) -> [u8; 3] {
        match self {
            Region::Background => [0, 0, 0],
            Region::Face => [255, 255, 0],
            Region::Mouth => [255, 0, 255],
            Region::Eyes => [0, 255, 255],
            Region::Neck => [128, 128, 128],
            Region::Torso => [255, 128, 0],
        }
    }

    /// The region of a `regions/` pixel: the nearest of [`Region::label_color`].
    pub fn from_label_color(rgb: [u8; 3]) -> Region {
        nearest(&Region::ALL, rgb, Region::label_color)
    }

    /// The region with label `v`, if any.
    pub fn from_label(v: u8) -> Option<Region> {
        Region::ALL.get(v as usize).copied()
    }

    /// True for every region that belongs to the head (face, mouth, eyes).
    pub fn is_head(self) -> bool {
        matches!(self, Region::Face | Region::Mouth | Region::Eyes)
    }
}

/// The region of `among` whose colour is nearest to `rgb`.
fn nearest(among: &[Region], rgb: [u8; 3], color: fn(Region) -> [u8; 3]) -> Region {
    let dist = |c: [u8; 3]| -> i32 { (0..3).map(|i| (c[i] as i32 - rgb[i] as i32).pow(2)).sum() };
    among
        .iter()
        .copied()
        .min_by_key(|r| dist(color(*r)))
        .unwrap_or(Region::Background)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn adnerf_parsing_reads_as_adnerf_writes_it() {
        // AD-NeRF's label image is BGR: head [255, 0, 0], neck [0, 255, 0], cloth [0, 0, 255].
        // On disk, read as RGB, the channels are reversed.
        let bgr_to_rgb = |c: [u8; 3]| [c[2], c[1], c[0]];
        assert_eq!(
            Region::from_parsing_color(bgr_to_rgb([255, 0, 0])),
            Region::Face
        );
        assert_eq!(
            Region::from_parsing_color(bgr_to_rgb([0, 255, 0])),
            Region::Neck
        );
        assert_eq!(
            Region::from_parsing_color(bgr_to_rgb([0, 0, 255])),
            Region::Torso
        );
        assert_eq!(Region::from_parsing_color([255; 3]), Region::Background);
        assert_eq!(Region::from_parsing_color([20, 30, 230]), Region::Face);
    }

    #[test]
    fn own_labels_round_trip_and_differ_from_parsing_colours() {
        for r in Region::ALL {
            assert_eq!(Region::from_label_color(r.label_color()), r);
            assert_ne!(r.label_color(), r.parsing_color(), "{r:?}");
        }
        for r in [
            Region::Background,
            Region::Face,
            Region::Neck,
            Region::Torso,
        ] {
            assert_eq!(Region::from_parsing_color(r.parsing_color()), r);
        }
    }
}
