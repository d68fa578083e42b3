//! What a trained model needs besides its weights to render frames of its scene: the camera,
//! the sampling range, the head's bounds, the background, the audio feature settings and a
//! default pose. The student trainer writes it beside its checkpoint as `render.json`, the
//! exporter copies it into the ONNX model's metadata, and renderers read it back from there.

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::audio::FeatureSource;
use crate::bounds::{Bounds, HeadRange};
use crate::camera::Intrinsics;
use crate::dataset::{Dataset, Split};
use crate::error::{Error, Result};
use crate::files::{read_json, write_json};

/// File name of the spec beside a student checkpoint.
pub const RENDER_SPEC_FILE: &str = "render.json";
/// File name of the background image beside a student checkpoint.
pub const BACKGROUND_FILE: &str = "background.png";

/// How to render frames of one trained scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RenderSpec {
    /// Camera intrinsics and image size of the training frames.
    pub intrinsics: Intrinsics,
    /// Sampling range along each ray (beam points lie in `[near, far]`).
    pub near: f32,
    pub far: f32,
    /// Video frame rate the audio windows follow.
    pub fps: f32,
    /// The head's bounds: rays that miss them are the background.
    pub bounds: Bounds,
    /// The background image's file name, relative to the spec's folder.
    pub background: String,
    /// Which front end made the training data's audio features: nldf's own (a WAV is
    /// turned into the same features at render time) or another one (AD-NeRF's DeepSpeech,
    /// say), whose features a render must be given.
    pub features: FeatureSource,
    /// Neighbouring audio frames the attention fuses (the model's `att_frames`).
    pub att_frames: usize,
    /// A camera-to-world matrix (row-major, OpenGL axes) to render from when no pose track
    /// is given: the first training frame's.
    pub default_pose: [[f32; 4]; 4],
}

impl RenderSpec {
    /// Where the scene's rays are sampled: the head's bounds within `[near, far]`.
    pub fn head_range(&self) -> HeadRange {
        HeadRange {
            bounds: self.bounds,
            near: self.near,
            far: self.far,
        }
    }

    /// The spec of a dataset, with the given head bounds and attention width.
    pub fn of_dataset(dataset: &Dataset, bounds: Bounds, att_frames: usize) -> RenderSpec {
        let default_pose = dataset
            .frames(Split::Train)
            .first()
            .map(|f| {
                let m = f.c2w.to_cols_array_2d();
                // glam is column-major: transpose into rows.
                std::array::from_fn(|r| std::array::from_fn(|c| m[c][r]))
            })
            .unwrap_or([
                [1.0, 0.0, 0.0, 0.0],
                [0.0, 1.0, 0.0, 0.0],
                [0.0, 0.0, 1.0, 0.0],
                [0.0, 0.0, 0.0, 1.0],
            ]);
        RenderSpec {
            intrinsics: dataset.intrinsics,
            near: dataset.near,
            far: dataset.far,
            fps: dataset.fps,
            bounds,
            background: BACKGROUND_FILE.to_string(),
            features: dataset.audio_source.clone(),
            att_frames,
            default_pose,
        }
    }

    /// Reads a spec, checking that its numbers make sense.
    pub fn load(path: &Path) -> Result<RenderSpec> {
        let spec: RenderSpec = read_json(path)?;
        spec.check().map_err(|e| Error::invalid(path, e))?;
        Ok(spec)
    }

    /// Writes the spec (atomically).
    pub fn save(&self, path: &Path) -> Result<()> {
        write_json(path, self)
    }

    /// What is wrong with the spec, if anything.
    pub fn check(&self) -> std::result::Result<(), String> {
        let i = &self.intrinsics;
        let finite = [i.focal, i.cx, i.cy, self.near, self.far, self.fps]
            .iter()
            .chain(self.bounds.lo.to_array().iter())
            .chain(self.bounds.hi.to_array().iter())
            .chain(self.default_pose.iter().flatten())
            .all(|v| v.is_finite());
        if !finite {
            return Err("holds a number that is not finite".into());
        }
        if i.width == 0 || i.height == 0 || i.focal <= 0.0 {
            return Err("needs a positive image size and focal length".into());
        }
        if !(self.near >= 0.0 && self.far > self.near) {
            return Err(format!(
                "needs 0 <= near < far, got near {} far {}",
                self.near, self.far
            ));
        }
        if self.fps <= 0.0 || self.att_frames == 0 {
            return Err("needs a positive fps and att_frames".into());
        }
        if (0..3).any(|a| self.bounds.hi[a] < self.bounds.lo[a]) {
            return Err("has head bounds with hi below lo".into());
        }
        if let FeatureSource::Nldf(cfg) = &self.features {
            cfg.validate().map_err(|e| e.to_string())?;
        }
        Ok(())
    }
}
