//! The ways of rendering on the frontier, each a [`FrameModel`] that times its whole
//! frames: an exported student in one runtime ([`OnnxPoint`]) and the teacher in candle
//! with its savings on or off ([`Timed`]).

use std::cell::RefCell;
use std::path::PathBuf;
use std::time::Instant;

use nldf_core::audio::neighbourhood;
use nldf_core::dataset::Frame;
use nldf_core::image::ImageRgb;
use nldf_export::WeightType;
use nldf_infer::{BackendKind, FrameRenderer};
use nldf_train::reports::eval::FrameModel;
use nldf_train::trainers::data::TrainData;
use nldf_train::trainers::teacher_trainer::TeacherModel;

use super::shared::precision_name;

/// An exported student in one runtime, rendering whole frames and timing each.
pub(crate) struct OnnxPoint {
    pub(crate) student: String,
    pub(crate) describe: String,
    pub(crate) short: String,
    pub(crate) precision: WeightType,
    pub(crate) kind: BackendKind,
    pub(crate) step: usize,
    pub(crate) macs_per_ray: f64,
    pub(crate) path: PathBuf,
    pub(crate) renderer: RefCell<FrameRenderer>,
    /// Each frame is rendered this many times smaller and upscaled bilinearly (1: not).
    pub(crate) upscale: u32,
    pub(crate) seconds: RefCell<Vec<f64>>,
}

impl OnnxPoint {
    /// The student's description, with the upscaling if any.
    pub(crate) fn model_name(&self) -> String {
        if self.upscale > 1 {
            format!("{}, upscaled {}x", self.describe, self.upscale)
        } else {
            self.describe.clone()
        }
    }

    fn audio(&self, data: &TrainData, frame: &Frame) -> Vec<f32> {
        let renderer = self.renderer.borrow();
        neighbourhood(
            &data.dataset.audio,
            frame.aud_id,
            renderer.info().audio.att_frames,
        )
    }
}

impl FrameModel for OnnxPoint {
    fn label(&self) -> String {
        let up = if self.upscale > 1 {
            format!(".up{}", self.upscale)
        } else {
            String::new()
        };
        format!(
            "{}.{}.{}{up}",
            self.student,
            precision_name(self.precision),
            self.kind.name()
        )
    }
    fn describe(&self) -> String {
        format!(
            "{} {} {}",
            self.model_name(),
            precision_name(self.precision),
            self.kind.name()
        )
    }
    fn step(&self) -> usize {
        self.step
    }
    fn macs_per_ray(&self) -> f64 {
        // Per ray of the frame it is scored at: an upscaled frame runs 1 / factor² of them.
        self.macs_per_ray / (self.upscale * self.upscale) as f64
    }
    fn render_frame(&self, data: &TrainData, frame: &Frame) -> nldf_train::error::Result<ImageRgb> {
        let audio = self.audio(data, frame);
        let started = Instant::now();
        let out = self
            .renderer
            .borrow_mut()
            .render(frame.c2w, &audio)
            .map_err(|e| {
                nldf_train::error::Error::Config(format!("{}: {e}", self.path.display()))
            })?;
        let image = out.image.upscaled(self.upscale);
        self.seconds
            .borrow_mut()
            .push(started.elapsed().as_secs_f64());
        Ok(image)
    }
}

/// The teacher in candle with its savings on or off, its whole frames timed.
pub(crate) struct Timed<'a> {
    pub(crate) run: &'a TeacherModel,
    /// Sample only inside the head's bounds.
    skip: bool,
    /// Leave a ray once its transmittance is spent.
    early_stop: bool,
    pub(crate) seconds: RefCell<Vec<f64>>,
}

impl<'a> Timed<'a> {
    pub(crate) fn new(run: &'a TeacherModel, skip: bool, early_stop: bool) -> Timed<'a> {
        Timed {
            run,
            skip,
            early_stop,
            seconds: RefCell::new(Vec::new()),
        }
    }

    /// What the savings left off add to the teacher's description and to its label.
    pub(crate) fn savings(&self) -> (&'static str, &'static str) {
        match (self.skip, self.early_stop) {
            (true, true) => ("", ""),
            (true, false) => (", no early stop", ".no_early_stop"),
            (false, true) => (", no skipping", ".no_skipping"),
            (false, false) => (", no skipping, no early stop", ".no_skipping.no_early_stop"),
        }
    }
}

impl FrameModel for Timed<'_> {
    fn label(&self) -> String {
        format!("{}{}", self.run.label(), self.savings().1)
    }
    fn describe(&self) -> String {
        format!("{}{}", self.run.describe(), self.savings().0)
    }
    fn step(&self) -> usize {
        self.run.step
    }
    fn macs_per_ray(&self) -> f64 {
        self.run.macs_per_ray()
    }
    fn render_frame(&self, data: &TrainData, frame: &Frame) -> nldf_train::error::Result<ImageRgb> {
        let started = Instant::now();
        let image = self
            .run
            .render_frame_with(data, frame, self.skip, self.early_stop)?;
        self.seconds
            .borrow_mut()
            .push(started.elapsed().as_secs_f64());
        Ok(image)
    }
}
