//! A dataset prepared from a test video, scored against the synthetic scene the video was
//! made from (`nldf synth --video`; `nldf bench prepare` runs [`score_prepared`]).
//!
//! The truth is the synthetic dataset: its train and val frames (the video's frames, by
//! `img_id`) with their cameras, `parsing/` (the person), its exact labels (`regions/`, or
//! `truth/regions/` for the second head: the head and the mouth) and `bc.png`. The prepared
//! dataset is in AD-NeRF's layout: `transforms_train.json` and `transforms_val.json` (the
//! video frame as `img_id`), `parsing/<img_id>.png` in AD-NeRF's colours,
//! `ori_imgs/<img_id>.lms` (68 landmarks) and `bc.jpg`. Frames the prepared dataset
//! dropped are counted and left out; the others are scored:
//!
//! - the cameras, after the one similarity no method can observe ([`crate::align`]):
//!   rotation error (mean, worst) and camera-centre error as a share of the true camera's
//!   distance to the head;
//! - the head mask: IoU of the prepared parsing's head with the true head, pooled over the
//!   frames (`Σ |A ∩ B| / Σ |A ∪ B|`) and the worst frame's;
//! - the background: PSNR of `bc.jpg` against the true `bc.png` on the pixels the person
//!   (head, neck or torso of the true parsing) covers in no frame of the recording;
//! - the lips: the share of the true mouth's pixels inside the polygon of the landmarks'
//!   outer lips (points 48-59), pooled over the frames whose true mouth is not empty.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use nldf_core::dataset::{LABELS_DIR, LANDMARKS_DIR, PARSING_DIR};
use nldf_core::landmarks::{LANDMARKS_EXT, Landmarks};
use nldf_core::region::Region;
use nldf_core::synth::TRUTH_LABELS_DIR;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::align::TrackErrors;
use crate::error::{Error, Result};
use crate::recording::{align_prepared, read_track};

/// Bar: mean rotation error, degrees, at most.
pub const ROTATION_MEAN_MAX_DEG: f64 = 2.0;
/// Bar: worst rotation error, degrees, at most.
pub const ROTATION_WORST_MAX_DEG: f64 = 5.0;
/// Bar: worst camera-centre error, a share of the true camera's distance, at most.
pub const POSITION_WORST_MAX: f64 = 0.01;
/// Bar: pooled head-mask IoU, at least.
pub const HEAD_IOU_MIN: f64 = 0.9;
/// Bar: the background's PSNR on the pixels the person never covers, dB, at least.
pub const BC_PSNR_MIN_DB: f64 = 30.0;
/// Bar: the share of the true mouth inside the landmarks' lips, at least.
pub const LIPS_COVERAGE_MIN: f64 = 0.8;
/// The PSNR given to identical images (whose error is 0).
pub const PSNR_CAP_DB: f64 = 100.0;

/// The bars, in the order of [`PrepareScores::checks`]: metric, unit, bar, and whether the
/// value must stay at most the bar (else at least).
const BARS: [(&str, &str, f64, bool); 6] = [
    ("rotation error, mean", "deg", ROTATION_MEAN_MAX_DEG, true),
    ("rotation error, worst", "deg", ROTATION_WORST_MAX_DEG, true),
    (
        "camera position error, worst",
        "% of distance",
        100.0 * POSITION_WORST_MAX,
        true,
    ),
    ("head-mask IoU, pooled", "", HEAD_IOU_MIN, false),
    (
        "background PSNR, never-covered pixels",
        "dB",
        BC_PSNR_MIN_DB,
        false,
    ),
    (
        "lips cover the true mouth",
        "%",
        100.0 * LIPS_COVERAGE_MIN,
        false,
    ),
];

/// The prepared background's file, and the one read where it is absent.
const BACKGROUND: [&str; 2] = ["bc.jpg", "bc.png"];

/// Every score of a prepared dataset against its truth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PrepareScores {
    /// Frames of the truth's recording (its train and val frames).
    pub frames_truth: usize,
    /// Frames both datasets have: the ones scored.
    pub frames_compared: usize,
    /// Frames of the truth the prepared dataset lacks.
    pub frames_missing: usize,
    /// Frames of the prepared dataset that the truth lacks (not scored).
    pub frames_extra: usize,
    /// The cameras' errors after the similarity, and the similarity.
    pub poses: TrackErrors,
    /// The prepared focal length over the true one (the same image size).
    pub focal_ratio: f64,
    /// Head-mask IoU pooled over the compared frames.
    pub head_iou: f64,
    /// The lowest IoU of one frame (among frames where either mask has a pixel).
    pub head_iou_worst: f64,
    /// That frame's `img_id`.
    pub head_iou_worst_img_id: i64,
    /// PSNR of the prepared background on the pixels the person never covers, dB
    /// (at most [`PSNR_CAP_DB`]).
    pub bc_psnr_db: f64,
    /// The number of those pixels.
    pub bc_pixels: usize,
    /// Share of the true mouth's pixels inside the landmarks' outer lips.
    pub lips_coverage: f64,
    /// Share of the lips polygon's pixels on the true mouth (same frames; no bar).
    pub lips_precision: f64,
    /// Compared frames whose true mouth has a pixel.
    pub mouth_frames: usize,
}

/// One score held against its bar.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Check {
    /// What is measured.
    pub metric: String,
    /// The measured value, in `unit`.
    pub value: f64,
    pub unit: String,
    /// The bar, e.g. `<= 2`.
    pub bar: String,
    pub pass: bool,
}

/// The scores, each bar's verdict, and whether all passed: what `nldf bench prepare`
/// writes as JSON.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScoreReport {
    pub truth: PathBuf,
    pub prepared: PathBuf,
    pub scores: PrepareScores,
    pub checks: Vec<Check>,
    pub passed: bool,
}

impl PrepareScores {
    /// Each bar of the issue with its verdict.
    pub fn checks(&self) -> Vec<Check> {
        let p = &self.poses;
        let values = [
            p.rotation_mean_deg,
            p.rotation_worst_deg,
            100.0 * p.position_worst,
            self.head_iou,
            self.bc_psnr_db,
            100.0 * self.lips_coverage,
        ];
        BARS.iter()
            .zip(values)
            .map(|(&(metric, unit, bar, at_most), value)| Check {
                metric: metric.into(),
                value,
                unit: unit.into(),
                bar: format!("{} {bar}", if at_most { "<=" } else { ">=" }),
                pass: if at_most { value <= bar } else { value >= bar },
            })
            .collect()
    }

    /// The scores with their verdicts.
    pub fn report(&self, truth: &Path, prepared: &Path) -> ScoreReport {
        let checks = self.checks();
        ScoreReport {
            truth: truth.to_path_buf(),
            prepared: prepared.to_path_buf(),
            passed: checks.iter().all(|c| c.pass),
            scores: self.clone(),
            checks,
        }
    }
}

/// Scores the dataset at `prepared` against the synthetic scene at `truth` (see the module
/// docs). Errors, one line naming the file: a file unreadable or missing (a frame's parsing
/// or landmarks, a transforms file, the background), a size that differs from the truth's,
/// a camera matrix that is not rigid, no frame in common.
pub fn score_prepared(truth: &Path, prepared: &Path) -> Result<PrepareScores> {
    let true_track = read_track(truth)?;
    let track = read_track(prepared)?;
    let (compared, poses) = align_prepared(&true_track, &track, prepared)?;
    let true_bc = read_rgb8(&truth.join("bc.png"))?;
    let files = FrameFiles {
        truth: truth.to_path_buf(),
        labels: truth_labels(truth)?,
        prepared: prepared.to_path_buf(),
        size: (true_bc.width, true_bc.height),
    };
    let compared_set: BTreeSet<i64> = compared.iter().copied().collect();
    let ids: Vec<i64> = true_track.poses.keys().copied().collect();
    let tally = (ids.into_par_iter())
        .map(|id| files.tally(id, compared_set.contains(&id)))
        .try_reduce(|| Tally::empty(files.size), |a, b| Ok(a.merge(b)))?;
    let (bc_psnr_db, bc_pixels) = background_psnr(prepared, &true_bc, &tally.person)?;
    if tally.mouth == 0 {
        let problem = "no compared frame of the truth shows a mouth";
        return Err(Error::invalid(&files.labels, problem));
    }
    let (head_iou_worst, head_iou_worst_img_id) = tally.worst.unwrap_or((1.0, compared[0]));
    Ok(PrepareScores {
        frames_truth: true_track.poses.len(),
        frames_compared: compared.len(),
        frames_missing: true_track.poses.len() - compared.len(),
        frames_extra: track.poses.len() - compared.len(),
        poses: poses.errors,
        focal_ratio: track.focal / true_track.focal,
        head_iou: ratio(tally.inter, tally.union),
        head_iou_worst,
        head_iou_worst_img_id,
        bc_psnr_db,
        bc_pixels,
        lips_coverage: ratio(tally.covered, tally.mouth),
        lips_precision: ratio(tally.covered, tally.lips),
        mouth_frames: tally.mouth_frames,
    })
}

/// The truth's exact labels: `regions/`, or the second head's `truth/regions/`.
pub(crate) fn truth_labels(truth: &Path) -> Result<PathBuf> {
    [LABELS_DIR, TRUTH_LABELS_DIR]
        .map(|d| truth.join(d))
        .into_iter()
        .find(|d| d.is_dir())
        .ok_or_else(|| {
            Error::invalid(
                truth.join(TRUTH_LABELS_DIR),
                "the truth has no exact labels (regions/ or truth/regions/): not a scene of \
                 nldf synth",
            )
        })
}

/// `a / b`, 1 when `b` is 0 (nothing to miss).
fn ratio(a: u64, b: u64) -> f64 {
    if b == 0 { 1.0 } else { a as f64 / b as f64 }
}

/// Where one frame's files are, and the truth's image size.
struct FrameFiles {
    truth: PathBuf,
    /// The truth's exact labels.
    labels: PathBuf,
    prepared: PathBuf,
    size: (u32, u32),
}

impl FrameFiles {
    /// Frame `id`'s contribution: the person it covers, and when `compared` its head masks
    /// and its mouth.
    fn tally(&self, id: i64, compared: bool) -> Result<Tally> {
        let parsing = |root: &Path| root.join(PARSING_DIR).join(format!("{id}.png"));
        let true_regions =
            read_regions(&parsing(&self.truth), self.size, Region::from_parsing_color)?;
        let mut tally = Tally::empty(self.size);
        for (p, r) in tally.person.iter_mut().zip(&true_regions) {
            *p = *r != Region::Background;
        }
        if !compared {
            return Ok(tally);
        }
        let regions = read_regions(
            &parsing(&self.prepared),
            self.size,
            Region::from_parsing_color,
        )?;
        let (inter, union) = mask_overlap(
            true_regions.iter().map(|r| r.is_head()),
            regions.iter().map(|r| r.is_head()),
        );
        (tally.inter, tally.union) = (inter, union);
        if union > 0 {
            tally.worst = Some((ratio(inter, union), id));
        }
        let labels = self.labels.join(format!("{id}.png"));
        let mouth: Vec<bool> = read_regions(&labels, self.size, Region::from_label_color)?
            .iter()
            .map(|&r| r == Region::Mouth)
            .collect();
        if mouth.iter().any(|&m| m) {
            let lms_path = self
                .prepared
                .join(LANDMARKS_DIR)
                .join(format!("{id}.{LANDMARKS_EXT}"));
            let lips = Landmarks::load(&lms_path)?.mouth_mask(self.size.0, self.size.1);
            let (covered, _) = mask_overlap(mouth.iter().copied(), lips.iter().copied());
            tally.covered = covered;
            tally.mouth = mouth.iter().filter(|&&m| m).count() as u64;
            tally.lips = lips.iter().filter(|&&m| m).count() as u64;
            tally.mouth_frames = 1;
        }
        Ok(tally)
    }
}

/// Sums over frames.
#[derive(Default)]
struct Tally {
    /// Head-mask intersection and union, in pixels.
    inter: u64,
    union: u64,
    /// The lowest one-frame IoU and its `img_id` (the lower `img_id` on a tie).
    worst: Option<(f64, i64)>,
    /// True mouth pixels, those inside the lips, and the lips polygon's pixels.
    mouth: u64,
    covered: u64,
    lips: u64,
    mouth_frames: usize,
    /// Pixels the person covers in some frame.
    person: Vec<bool>,
}

impl Tally {
    fn empty((w, h): (u32, u32)) -> Tally {
        Tally {
            person: vec![false; w as usize * h as usize],
            ..Default::default()
        }
    }

    fn merge(mut self, other: Tally) -> Tally {
        self.inter += other.inter;
        self.union += other.union;
        self.worst = match (self.worst, other.worst) {
            (Some(a), Some(b)) => Some(if (b.0, b.1) < (a.0, a.1) { b } else { a }),
            (a, b) => a.or(b),
        };
        self.mouth += other.mouth;
        self.covered += other.covered;
        self.lips += other.lips;
        self.mouth_frames += other.mouth_frames;
        for (p, q) in self.person.iter_mut().zip(other.person) {
            *p |= q;
        }
        self
    }
}

/// `(|A ∩ B|, |A ∪ B|)` of two masks.
fn mask_overlap(a: impl Iterator<Item = bool>, b: impl Iterator<Item = bool>) -> (u64, u64) {
    a.zip(b).fold((0, 0), |(i, u), (x, y)| {
        (i + (x && y) as u64, u + (x || y) as u64)
    })
}

/// An 8-bit RGB image.
struct Rgb8 {
    width: u32,
    height: u32,
    bytes: Vec<u8>,
}

/// Reads a PNG or JPEG as 8-bit RGB.
fn read_rgb8(path: &Path) -> Result<Rgb8> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let img = image::load_from_memory(&bytes)
        .map_err(|e| Error::invalid(path, format!("not a readable image: {e}")))?
        .to_rgb8();
    Ok(Rgb8 {
        width: img.width(),
        height: img.height(),
        bytes: img.into_raw(),
    })
}

/// Reads a label image of `size`, each pixel the region `read` gives its colour.
pub(crate) fn read_regions(
    path: &Path,
    size: (u32, u32),
    read: fn([u8; 3]) -> Region,
) -> Result<Vec<Region>> {
    let img = read_rgb8(path)?;
    check_size(path, &img, size)?;
    Ok(img
        .bytes
        .chunks_exact(3)
        .map(|c| read([c[0], c[1], c[2]]))
        .collect())
}

fn check_size(path: &Path, img: &Rgb8, (w, h): (u32, u32)) -> Result<()> {
    if (img.width, img.height) != (w, h) {
        return Err(Error::invalid(
            path,
            format!(
                "is {}x{}, the truth's frames are {w}x{h}",
                img.width, img.height
            ),
        ));
    }
    Ok(())
}

/// The prepared background's PSNR against `truth` on the pixels `person` leaves free, and
/// their number.
fn background_psnr(prepared: &Path, truth: &Rgb8, person: &[bool]) -> Result<(f64, usize)> {
    let path = BACKGROUND
        .iter()
        .map(|name| prepared.join(name))
        .find(|p| p.is_file())
        .unwrap_or_else(|| prepared.join(BACKGROUND[0]));
    let bc = read_rgb8(&path)?;
    check_size(&path, &bc, (truth.width, truth.height))?;
    let free: Vec<bool> = person.iter().map(|&p| !p).collect();
    psnr_on(&bc.bytes, &truth.bytes, &free)
        .map(|db| (db, free.iter().filter(|&&f| f).count()))
        .ok_or_else(|| {
            Error::invalid(
                prepared.join(BACKGROUND[0]),
                "the person covers every pixel in some frame of the truth: no background to \
                 score",
            )
        })
}

/// PSNR in dB of two 8-bit RGB images on the pixels where `keep` holds (peak 255; at most
/// [`PSNR_CAP_DB`]); `None` when no pixel is kept.
fn psnr_on(a: &[u8], b: &[u8], keep: &[bool]) -> Option<f64> {
    let (mut sum, mut n) = (0.0f64, 0usize);
    for ((pa, pb), _) in a
        .chunks_exact(3)
        .zip(b.chunks_exact(3))
        .zip(keep)
        .filter(|(_, k)| **k)
    {
        for c in 0..3 {
            let d = pa[c] as f64 - pb[c] as f64;
            sum += d * d;
        }
        n += 3;
    }
    if n == 0 {
        return None;
    }
    let mse = sum / n as f64 / (255.0 * 255.0);
    Some(if mse == 0.0 {
        PSNR_CAP_DB
    } else {
        (-10.0 * mse.log10()).min(PSNR_CAP_DB)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `w x h` mask of the square `[x0, x1) x [y0, y1)`.
    fn square(w: usize, h: usize, (x0, x1): (usize, usize), (y0, y1): (usize, usize)) -> Vec<bool> {
        (0..w * h)
            .map(|p| (x0..x1).contains(&(p % w)) && (y0..y1).contains(&(p / w)))
            .collect()
    }

    #[test]
    fn the_iou_of_two_offset_squares() {
        // 10 x 10 squares offset by 5 along x and 2 along y: 5 x 8 = 40 shared pixels of
        // 100 + 100 - 40 = 160, an IoU of 0.25.
        let a = square(32, 32, (4, 14), (6, 16));
        let b = square(32, 32, (9, 19), (8, 18));
        let (inter, union) = mask_overlap(a.iter().copied(), b.iter().copied());
        assert_eq!((inter, union), (40, 160));
        assert_eq!(ratio(inter, union), 0.25);
        assert_eq!(
            mask_overlap(a.iter().copied(), a.iter().copied()),
            (100, 100)
        );
    }

    #[test]
    fn background_psnr_on_a_known_image_counts_only_the_kept_pixels() {
        // Two 4 x 4 images 10 levels apart on every channel, except the pixels that are
        // not kept, which differ wildly: MSE (10/255)^2, PSNR 20 log10(25.5) = 28.1308 dB.
        let a = vec![100u8; 4 * 4 * 3];
        let mut b = vec![110u8; 4 * 4 * 3];
        let keep = square(4, 4, (0, 4), (0, 2));
        for (p, k) in keep.iter().enumerate() {
            if !k {
                b[3 * p..3 * p + 3].copy_from_slice(&[255, 0, 255]);
            }
        }
        let db = psnr_on(&a, &b, &keep).unwrap();
        assert!((db - 20.0 * 25.5f64.log10()).abs() < 1e-12, "{db}");
        assert_eq!(psnr_on(&a, &a, &keep), Some(PSNR_CAP_DB));
        assert_eq!(psnr_on(&a, &b, &[false; 16]), None);
    }

    #[test]
    fn lips_coverage_of_a_known_polygon() {
        // The true mouth: columns 10..20, rows 10..14 (40 pixels). The lips polygon is the
        // rectangle with corners (14.5, 9.5) and (24.5, 13.5): pixel centres in columns
        // 15..=24 and rows 10..=13, of which columns 15..20 are on the mouth: 20 of 40.
        let (w, h) = (32u32, 24u32);
        let mouth = square(w as usize, h as usize, (10, 20), (10, 14));
        let mut points = vec![[0.0f32; 2]; 68];
        let corners = [[14.5, 9.5], [24.5, 9.5], [24.5, 13.5], [14.5, 13.5]];
        for k in 0..12 {
            points[48 + k] = corners[k * 4 / 12];
        }
        let lips = Landmarks { points }.mouth_mask(w, h);
        let (covered, _) = mask_overlap(mouth.iter().copied(), lips.iter().copied());
        let n_mouth = mouth.iter().filter(|&&m| m).count() as u64;
        let n_lips = lips.iter().filter(|&&m| m).count() as u64;
        assert_eq!((covered, n_mouth, n_lips), (20, 40, 40));
        assert_eq!(ratio(covered, n_mouth), 0.5);
    }

    #[test]
    fn the_worst_frame_survives_merging_in_any_order() {
        let frame = |iou: f64, id: i64| Tally {
            worst: Some((iou, id)),
            ..Tally::empty((2, 2))
        };
        let ids = [(0.9, 4), (0.7, 9), (0.7, 2), (0.95, 1)];
        for rotate in 0..4 {
            let merged = (0..4)
                .map(|k| ids[(k + rotate) % 4])
                .fold(Tally::empty((2, 2)), |acc, (v, id)| acc.merge(frame(v, id)));
            assert_eq!(merged.worst, Some((0.7, 2)));
        }
    }
}
