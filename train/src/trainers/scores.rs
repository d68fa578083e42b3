//! Image scores of rendered frames against their ground truth: PSNR and SSIM over the whole
//! frame and inside the head (the headline: about half of a frame is background copied from
//! `bc`), PSNR inside the mouth, with NaN renders counted instead of hidden. Training scores its
//! validation frames with them, evaluation its whole splits.

use nldf_core::dataset::{Frame, Split};
use nldf_core::image::ImageRgb;
use nldf_core::metrics::{cap_psnr, psnr, psnr_masked, ssim, ssim_with_mask};
use nldf_core::region::Region;

use crate::error::Result;
use crate::trainers::data::TrainData;

/// Image scores averaged over frames.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Scores {
    pub psnr: f64,
    pub ssim: f64,
    /// PSNR inside the head (face, eyes, mouth; when the dataset has region masks).
    #[serde(alias = "face_psnr")]
    pub head_psnr: Option<f64>,
    /// SSIM over the windows centred inside the head.
    #[serde(default)]
    pub head_ssim: Option<f64>,
    /// PSNR inside the mouth region (when the dataset has parsing masks).
    pub mouth_psnr: Option<f64>,
    pub frames: usize,
    /// Frames whose render holds a NaN or infinite value: their scores are NaN, and so are
    /// the means above.
    #[serde(default)]
    pub non_finite: usize,
}

/// Scores of one frame: over the whole frame and, where the dataset has region masks,
/// inside the head and the mouth (each `None` where the region is empty or unknown).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameScores {
    /// PSNR, capped at [`nldf_core::metrics::PSNR_CAP`] dB (NaN stays NaN).
    pub psnr: f64,
    pub ssim: f64,
    /// PSNR inside the head, capped likewise.
    pub head_psnr: Option<f64>,
    /// SSIM over the windows centred inside the head.
    pub head_ssim: Option<f64>,
    /// PSNR inside the mouth, capped likewise.
    pub mouth_psnr: Option<f64>,
}

/// The scores of `render` against `truth` (the SSIM map computed once for the whole frame
/// and the head), inside `regions` where given.
pub fn frame_scores(
    render: &ImageRgb,
    truth: &ImageRgb,
    regions: Option<&[Region]>,
) -> Result<FrameScores> {
    let psnr = cap_psnr(psnr(render, truth)?);
    let Some(regions) = regions else {
        return Ok(FrameScores {
            psnr,
            ssim: ssim(render, truth)?,
            head_psnr: None,
            head_ssim: None,
            mouth_psnr: None,
        });
    };
    let head: Vec<bool> = regions.iter().map(|r| r.is_head()).collect();
    let mouth: Vec<bool> = regions.iter().map(|r| *r == Region::Mouth).collect();
    let (ssim, head_ssim) = ssim_with_mask(render, truth, &head)?;
    Ok(FrameScores {
        psnr,
        ssim,
        head_psnr: psnr_masked(render, truth, &head)?.map(cap_psnr),
        head_ssim,
        mouth_psnr: psnr_masked(render, truth, &mouth)?.map(cap_psnr),
    })
}

/// Renders `n` validation frames spread evenly over the validation split (the training
/// split when it is empty) with `render` and scores them.
pub fn score_validation_frames(
    data: &TrainData,
    n: usize,
    render: &dyn Fn(&Frame) -> Result<ImageRgb>,
) -> Result<Scores> {
    let frames = data.dataset.frames(Split::Val);
    let frames = if frames.is_empty() {
        data.dataset.frames(Split::Train)
    } else {
        frames
    };
    let n = n.clamp(1, frames.len().max(1));
    let mut pairs = Vec::with_capacity(n);
    for k in 0..n.min(frames.len()) {
        let frame = &frames[k * frames.len() / n];
        let truth = data.dataset.load_image(frame)?;
        let regions = data.dataset.load_regions(frame)?;
        pairs.push((render(frame)?, truth, regions));
    }
    score_frames(&pairs)
}

/// Scores of rendered frames against their ground truth and optional region masks. A
/// render holding a NaN or infinite value makes every mean NaN and is counted in
/// [`Scores::non_finite`]: it never scores as a good frame.
pub fn score_frames(pairs: &[(ImageRgb, ImageRgb, Option<Vec<Region>>)]) -> Result<Scores> {
    let (mut p, mut s) = (0.0, 0.0);
    let (mut head, mut head_ssim, mut mouth) = (Vec::new(), Vec::new(), Vec::new());
    let mut non_finite = 0;
    for (render, truth, regions) in pairs {
        non_finite += usize::from(render.non_finite_values() > 0);
        let f = frame_scores(render, truth, regions.as_deref())?;
        p += f.psnr;
        s += f.ssim;
        head.extend(f.head_psnr);
        head_ssim.extend(f.head_ssim);
        mouth.extend(f.mouth_psnr);
    }
    let n = pairs.len().max(1) as f64;
    let mean = |v: Vec<f64>| (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64);
    Ok(Scores {
        psnr: p / n,
        ssim: s / n,
        head_psnr: mean(head),
        head_ssim: mean(head_ssim),
        mouth_psnr: mean(mouth),
        frames: pairs.len(),
        non_finite,
    })
}
