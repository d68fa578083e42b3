//! The upsampler benchmark's frame graph in one runtime: renders a frame from its camera
//! and audio chunk, timing each frame.

use std::cell::{Cell, RefCell};
use std::time::Instant;

use nldf_core::audio::{Waveform, read_wav};
use nldf_core::dataset::{AUDIO_WAV, Frame, Split, VOICE_DIR};
use nldf_core::image::ImageRgb;
use nldf_export::WeightType;
use nldf_infer::BackendKind;
use nldf_infer::frame_graph::FrameGraph;
use nldf_model::FrameGraphFile;
use nldf_train::reports::eval::FrameModel;
use nldf_train::trainers::data::TrainData;

use super::shared::precision_name;

/// The frame graph with the upsampler in one runtime, timing its frames.
pub(super) struct UpsampledPoint {
    pub(super) label: String,
    pub(super) precision: WeightType,
    pub(super) kind: BackendKind,
    pub(super) step: usize,
    pub(super) graph: RefCell<FrameGraph>,
    pub(super) model: FrameGraphFile,
    /// The split being rendered (its track is the voice split's own) and its 16 kHz track.
    pub(super) split: Cell<Split>,
    pub(super) wave: RefCell<Option<(Split, Waveform)>>,
    pub(super) seconds: RefCell<Vec<f64>>,
}

impl UpsampledPoint {
    fn samples(&self, data: &TrainData, frame: &Frame) -> nldf_train::error::Result<Vec<f32>> {
        let root = &data.dataset.root;
        let split = self.split.get();
        let mut wave = self.wave.borrow_mut();
        if wave.as_ref().map(|(s, _)| *s) != Some(split) {
            let path = if split == Split::Voice {
                root.join(VOICE_DIR).join(AUDIO_WAV)
            } else {
                root.join(AUDIO_WAV)
            };
            *wave = Some((split, read_wav(&path)?));
        }
        let samples = &wave
            .as_ref()
            .map(|(_, w)| w.samples.as_slice())
            .unwrap_or(&[]);
        Ok(self.model.audio.chunk(samples, frame.aud_id))
    }
}

impl FrameModel for UpsampledPoint {
    fn label(&self) -> String {
        self.label.clone()
    }
    fn describe(&self) -> String {
        format!(
            "upsampler x{} {} {}",
            self.model.upsample,
            precision_name(self.precision),
            self.kind.name()
        )
    }
    fn step(&self) -> usize {
        self.step
    }
    fn macs_per_ray(&self) -> f64 {
        0.0
    }
    fn render_frame(&self, data: &TrainData, frame: &Frame) -> nldf_train::error::Result<ImageRgb> {
        let chunk = self.samples(data, frame)?;
        let started = Instant::now();
        let out = self
            .graph
            .borrow_mut()
            .render(frame.c2w, &chunk)
            .map_err(|e| {
                nldf_train::error::Error::Config(format!("{}: {e}", self.model.path.display()))
            })?;
        self.seconds
            .borrow_mut()
            .push(started.elapsed().as_secs_f64());
        Ok(out.image)
    }
}
