//! What `nldf prepare` is asked to do: a [`PrepareJob`]'s settings, their defaults and the
//! checks that refuse settings no video can be prepared with.

use std::path::PathBuf;

use crate::error::{Error, Result};
use crate::parsing::ParsingConfig;
use crate::pose::PoseConfig;
use crate::video::{self, Probe, Window};

/// AD-NeRF's focal length, 1200 px at 450 x 450, scaled to the output size: the default,
/// since landmarks cannot tell the focal length.
pub const DEFAULT_FOCAL_AT_450: f32 = 1200.0;
/// The largest size frames are analysed at by default (see [`PrepareJob::analysis_size`]).
pub const ANALYSIS_MAX: u32 = 512;
/// The smallest size, in pixels, that frames are written, analysed or posed at.
pub const MIN_SIZE: u32 = 32;
/// The largest size, in pixels, that frames are written, analysed or posed at.
pub const MAX_SIZE: u32 = 2048;

/// What to prepare.
#[derive(Debug, Clone)]
pub struct PrepareJob {
    pub video: PathBuf,
    pub out: PathBuf,
    /// Output frames are `size x size`.
    pub size: u32,
    /// Focal length in output pixels (default [`DEFAULT_FOCAL_AT_450`] scaled).
    pub focal: Option<f32>,
    /// Seconds into the clip to start at.
    pub start: f64,
    /// Seconds to read (to the end when `None`).
    pub seconds: Option<f64>,
    /// The square crop `[x, y, side]` in source pixels (the centred square when `None`).
    pub crop: Option<[u32; 3]>,
    /// Fewest frames with one face to train on.
    pub min_frames: usize,
    /// Replace an existing output folder.
    pub force: bool,
    pub pose: PoseConfig,
    /// Resample the video to this constant frame rate (also taking a variable-rate one);
    /// `None` keeps its own rate.
    pub fps: Option<f64>,
    /// Analyse the frames (landmarks, tracks, poses, masks, background) at this size, then
    /// shrink the dataset to `size` ([`crate::resample`]). Default: the crop's side, at
    /// most [`ANALYSIS_MAX`], and never below `size`.
    pub analysis_size: Option<u32>,
    /// Where the person splits into head, neck and torso.
    pub parsing: ParsingConfig,
}

impl PrepareJob {
    /// Why this job's settings cannot be used, as an error naming the flag; checked before
    /// anything is read or installed.
    pub fn check(&self) -> Result<()> {
        let sizes = [
            ("--size", Some(self.size), ""),
            ("--analysis-size", self.analysis_size, ""),
            (
                "--pose-size",
                Some(self.pose.pose_size).filter(|&s| s != 0),
                " (or 0, off)",
            ),
        ];
        for (flag, size, or) in sizes {
            if let Some(s) = size.filter(|s| !(MIN_SIZE..=MAX_SIZE).contains(s)) {
                return Err(Error::Argument(format!(
                    "{flag} {s} is not in {MIN_SIZE}..={MAX_SIZE} pixels{or}"
                )));
            }
        }
        if !(self.start.is_finite() && self.start >= 0.0) {
            return Err(Error::Argument(format!(
                "--start {} is not a time in seconds >= 0",
                self.start
            )));
        }
        if let Some(s) = self.seconds.filter(|s| !(s.is_finite() && *s > 0.0)) {
            return Err(Error::Argument(format!(
                "--seconds {s} is not a duration in seconds > 0"
            )));
        }
        if let Some(f) = self.focal.filter(|f| !(f.is_finite() && *f > 0.0)) {
            return Err(Error::Argument(format!(
                "--focal {f} is not a focal length in pixels > 0"
            )));
        }
        if let Some(f) = self
            .fps
            .filter(|f| !(f.is_finite() && (1.0..=120.0).contains(f)))
        {
            return Err(Error::Argument(format!(
                "--fps {f} is not a frame rate in 1..=120"
            )));
        }
        self.pose.validate()
    }

    /// The crop and window this job reads from a probed video, checked against it.
    pub(crate) fn window(&self, probe: &Probe) -> Result<Window> {
        let crop = self
            .crop
            .unwrap_or_else(|| video::centre_square(probe.width, probe.height));
        let [x, y, side] = crop;
        if side == 0
            || x.saturating_add(side) > probe.width
            || y.saturating_add(side) > probe.height
        {
            return Err(Error::Argument(format!(
                "--crop {x},{y},{side} does not fit the {}x{} video",
                probe.width, probe.height
            )));
        }
        Ok(Window {
            start: self.start,
            seconds: self.seconds,
            crop,
            size: self.size,
            fps: self.fps,
        })
    }

    /// The size frames are analysed at for a crop of `side` source pixels (see
    /// [`PrepareJob::analysis_size`]).
    pub fn analysis(&self, side: u32) -> u32 {
        self.analysis_size
            .unwrap_or(side.min(ANALYSIS_MAX))
            .max(self.size)
    }

    /// The focal length in output pixels.
    pub fn focal(&self) -> f32 {
        self.focal
            .unwrap_or(DEFAULT_FOCAL_AT_450 * self.size as f32 / 450.0)
    }
}
