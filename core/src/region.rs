//! Region labels of a frame (the `parsing/` masks): which pixels are background, face, mouth
//! or eyes. Used for face-biased ray batches and for region metrics such as mouth PSNR.

/// One pixel's region. Stored in `parsing/<img_id>.png` as the colour [`Region::color`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Region {
    Background = 0,
    Face = 1,
    Mouth = 2,
    Eyes = 3,
}

impl Region {
    /// All regions, in label order.
    pub const ALL: [Region; 4] = [
        Region::Background,
        Region::Face,
        Region::Mouth,
        Region::Eyes,
    ];

    /// The colour of this region in a parsing PNG.
    pub fn color(self) -> [u8; 3] {
        match self {
            Region::Background => [255, 255, 255],
            Region::Face => [255, 0, 0],
            Region::Mouth => [0, 255, 0],
            Region::Eyes => [0, 0, 255],
        }
    }

    /// The region whose colour is nearest to `rgb` (parsing PNGs may be JPEG-damaged).
    pub fn from_color(rgb: [u8; 3]) -> Region {
        let dist =
            |c: [u8; 3]| -> i32 { (0..3).map(|i| (c[i] as i32 - rgb[i] as i32).pow(2)).sum() };
        Region::ALL
            .into_iter()
            .min_by_key(|r| dist(r.color()))
            .unwrap_or(Region::Background)
    }

    /// The region with label `v`, if any.
    pub fn from_label(v: u8) -> Option<Region> {
        Region::ALL.get(v as usize).copied()
    }

    /// True for every region that belongs to the head.
    pub fn is_head(self) -> bool {
        self != Region::Background
    }
}
