//! A trained student that renders: its folder, configuration and weights.

use std::path::{Path, PathBuf};

use candle_core::{Device, Tensor};
use candle_nn::VarMap;
use nldf_core::beam::encode_beams_parallel;
use nldf_core::camera::Camera;
use nldf_core::dataset::Frame;
use nldf_core::image::ImageRgb;
use nldf_core::rays::head_rays;
use nldf_core::run_files::CONFIG_FILE;

use crate::error::Result;
use crate::networks::nn::new_varmap;
use crate::networks::student::{Student, student};
use crate::trainers::checkpoint::open_checkpoint;
use crate::trainers::config::{RunConfig, StudentRunConfig, read_config};
use crate::trainers::data::TrainData;
use crate::trainers::scores::{Scores, score_validation_frames};

/// Rays per forward pass when rendering.
const RENDER_CHUNK: usize = 8192;

/// A trained student, for rendering: its folder, configuration and weights, and the step
/// they were saved at. [`StudentModel::open`] reads nothing of the training state (the
/// optimizer's moments, the beam pool), so a model renders whether or not its run can
/// resume.
pub struct StudentModel {
    pub dir: PathBuf,
    pub cfg: StudentRunConfig,
    pub varmap: VarMap,
    pub student: Student,
    /// Steps done.
    pub step: usize,
    /// Training seconds the checkpoint it was opened from records, across resumes (0 for
    /// a new model; a run's own clock is its `elapsed()`).
    pub trained_s: f64,
}

impl StudentModel {
    /// Loads the trained student in `dir`: its `config.json` and weights.
    pub fn open(dir: &Path) -> Result<StudentModel> {
        let mut model = Self::build(dir, read_config(&dir.join(CONFIG_FILE))?)?;
        let (step, clock) = open_checkpoint(dir, &model.varmap, None)?;
        (model.step, model.trained_s) = (step, clock.elapsed());
        Ok(model)
    }

    /// The network of `cfg` at step 0, weights as the variable builder made them.
    pub(crate) fn build(dir: &Path, cfg: StudentRunConfig) -> Result<StudentModel> {
        cfg.check()?;
        let (varmap, vb) = new_varmap();
        let student = student(&cfg.model, vb)?;
        Ok(StudentModel {
            dir: dir.to_path_buf(),
            cfg,
            varmap,
            student,
            step: 0,
            trained_s: 0.0,
        })
    }

    /// Audio codes of frames.
    ///
    /// # Shapes
    /// - returns `[aud_ids.len(), audio_dim]`
    pub fn audio_codes(&self, data: &TrainData, aud_ids: &[usize]) -> Result<Tensor> {
        let windows = data.neighbourhoods(aud_ids, self.cfg.model.audio.att_frames)?;
        Ok(self.student.audio_codes(&windows)?)
    }

    /// Renders a whole frame (any split): the rays that meet the head's bounds
    /// ([`head_rays`]) go through the student, the other pixels are the background.
    pub fn render_frame(&self, data: &TrainData, frame: &Frame) -> Result<ImageRgb> {
        let ds = &data.dataset;
        let code = self.audio_codes(data, &[frame.aud_id])?;
        self.render_view(&ds.camera(frame), &ds.background, &code, data)
    }

    /// The image seen by `camera` with one audio code: the student's pixel where the ray
    /// meets the head's bounds, `background` elsewhere.
    ///
    /// # Shapes
    /// - `code`: `[1, audio_dim]`; `background` is the camera's image size
    pub fn render_view(
        &self,
        camera: &Camera,
        background: &ImageRgb,
        code: &Tensor,
        data: &TrainData,
    ) -> Result<ImageRgb> {
        let ds = &data.dataset;
        let head = head_rays(camera, &data.head_range());
        let mut image = background.clone();
        let spec = &self.cfg.model.beam;
        for (c, chunk) in head.pixels.chunks(RENDER_CHUNK).enumerate() {
            let lo = c * RENDER_CHUNK;
            let sub = head.rays.slice(lo..lo + chunk.len());
            let beams = encode_beams_parallel(&sub, ds.near, ds.far, spec, None);
            let beams = Tensor::from_vec(beams, (chunk.len(), spec.encoded_len()), &Device::Cpu)?;
            let codes = code
                .broadcast_as((chunk.len(), code.dim(1)?))?
                .contiguous()?;
            let out = self.student.mlp.forward_fused(&beams, &codes, false)?;
            let bg = background.gather(chunk);
            let pixels = out.pixels(&Tensor::from_vec(bg, (chunk.len(), 3), &Device::Cpu)?)?;
            let pixels: Vec<f32> = pixels.flatten_all()?.to_vec1()?;
            image.paint(chunk, &pixels);
        }
        Ok(image)
    }

    /// Renders `n` validation frames spread evenly over the split and scores them.
    pub fn validation_scores(&self, data: &TrainData, n: usize) -> Result<Scores> {
        score_validation_frames(data, n, &|f| self.render_frame(data, f))
    }
}
