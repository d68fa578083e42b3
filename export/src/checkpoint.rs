//! A trained student as nldf-train leaves it in `RUN/student/`, read without candle:
//! `model.safetensors` (f32 weights, the step in its metadata), `config.json` (the resolved
//! config, whose `model` field is the student's shape), `render.json` (the
//! [`RenderSpec`]) and the background image it names.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use nldf_core::image::ImageRgb;
use nldf_core::render_spec::RenderSpec;
use nldf_core::run_files::{
    CHECKPOINT_VERSION_KEY, CONFIG_FILE, MODEL_FILE, RENDER_SPEC_FILE, checkpoint_version_problem,
};
use nldf_core::student_config::StudentConfig;

use crate::error::{Error, Result};

/// One f32 tensor of the checkpoint.
#[derive(Debug, Clone, PartialEq)]
pub struct Weight {
    pub shape: Vec<usize>,
    pub data: Vec<f32>,
}

/// A student folder, read and checked.
#[derive(Debug, Clone)]
pub struct StudentCheckpoint {
    /// The folder.
    pub dir: PathBuf,
    /// The network's shape.
    pub shape: StudentConfig,
    /// How to render frames of the scene.
    pub spec: RenderSpec,
    /// Training step of the weights.
    pub step: u64,
    /// The background, an 8-bit RGB PNG of the spec's image size.
    pub background_png: Vec<u8>,
    weights: HashMap<String, Weight>,
}

impl StudentCheckpoint {
    /// Reads `dir` (`model.safetensors`, `config.json`, `render.json`, the background).
    pub fn open(dir: &Path) -> Result<StudentCheckpoint> {
        let config_path = dir.join(CONFIG_FILE);
        let config: serde_json::Value = nldf_core::files::read_json(&config_path)?;
        let model = config.get("model").ok_or_else(|| {
            Error::invalid(&config_path, "has no `model` field (not a student config?)")
        })?;
        if let Some(key) = missing_key(model) {
            return Err(Error::invalid(
                &config_path,
                format!("`{key}` is missing (not a config the trainer wrote?)"),
            ));
        }
        let shape: StudentConfig = serde_json::from_value(model.clone()).map_err(|e| {
            Error::invalid(
                &config_path,
                format!("`model` is not a student config: {e}"),
            )
        })?;
        shape
            .check()
            .map_err(|e| Error::invalid(&config_path, e.to_string()))?;

        let spec_path = dir.join(RENDER_SPEC_FILE);
        let spec = RenderSpec::load(&spec_path)?;
        if spec.att_frames != shape.audio.att_frames
            || spec.features.window() != shape.audio.window
            || spec.features.n_features() != shape.audio.n_features
        {
            return Err(Error::invalid(
                &spec_path,
                format!(
                    "att_frames {}, window {} and features {} disagree with {}'s {}, {} and {}",
                    spec.att_frames,
                    spec.features.window(),
                    spec.features.n_features(),
                    config_path.display(),
                    shape.audio.att_frames,
                    shape.audio.window,
                    shape.audio.n_features
                ),
            ));
        }

        let background_path = dir.join(&spec.background);
        let background = ImageRgb::load(&background_path)?;
        let k = &spec.intrinsics;
        if (background.width, background.height) != (k.width, k.height) {
            return Err(Error::invalid(
                &background_path,
                format!(
                    "is {}x{}, the render spec's image is {}x{}",
                    background.width, background.height, k.width, k.height
                ),
            ));
        }
        let mut background_png = Vec::new();
        let encoder = image::codecs::png::PngEncoder::new(&mut background_png);
        image::ImageEncoder::write_image(
            encoder,
            &background.to_rgb8(),
            k.width,
            k.height,
            image::ExtendedColorType::Rgb8,
        )
        .map_err(|e| Error::invalid(&background_path, format!("cannot encode PNG: {e}")))?;

        let (weights, step) = read_weights(&dir.join(MODEL_FILE))?;
        Ok(StudentCheckpoint {
            dir: dir.to_path_buf(),
            shape,
            spec,
            step,
            background_png,
            weights,
        })
    }

    /// The weight whose largest magnitude is largest, and that magnitude (`None` without
    /// weights).
    pub fn largest_weight(&self) -> Option<(&str, f32)> {
        self.weights
            .iter()
            .map(|(name, w)| {
                let m = w.data.iter().fold(0.0f32, |m, v| m.max(v.abs()));
                (name.as_str(), m)
            })
            .max_by(|a, b| a.1.total_cmp(&b.1).then_with(|| b.0.cmp(a.0)))
    }

    /// The weight `name`, checked to have shape `shape`.
    pub fn weight(&self, name: &str, shape: &[usize]) -> Result<&[f32]> {
        checked_weight(&self.weights, &self.dir, name, shape)
    }
}

/// The weight `name` of the checkpoint in `dir`, checked to have shape `shape`.
pub(crate) fn checked_weight<'a>(
    weights: &'a HashMap<String, Weight>,
    dir: &Path,
    name: &str,
    shape: &[usize],
) -> Result<&'a [f32]> {
    let path = dir.join(MODEL_FILE);
    let w = weights
        .get(name)
        .ok_or_else(|| Error::invalid(&path, format!("lacks weight `{name}`")))?;
    if w.shape != shape {
        return Err(Error::invalid(
            &path,
            format!(
                "weight `{name}` has shape {:?}, {} says {:?}",
                w.shape, CONFIG_FILE, shape
            ),
        ));
    }
    Ok(&w.data)
}

/// The f32 tensors of a safetensors file and the `step` of its metadata (0 when absent).
fn read_weights(path: &Path) -> Result<(HashMap<String, Weight>, u64)> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    parse_weights(path, &bytes)
}

/// The f32 tensors of safetensors `bytes` and the `step` of their metadata (0 when
/// absent), refusing non-finite weights and another kind than a student's; `path` names the
/// bytes in errors.
pub fn parse_weights(path: &Path, bytes: &[u8]) -> Result<(HashMap<String, Weight>, u64)> {
    parse_weights_of(path, bytes, "student")
}

/// [`parse_weights`] for checkpoints of kind `expected` (`student`, `upsampler`).
pub fn parse_weights_of(
    path: &Path,
    bytes: &[u8],
    expected: &str,
) -> Result<(HashMap<String, Weight>, u64)> {
    let (_, meta) = safetensors::SafeTensors::read_metadata(bytes)
        .map_err(|e| Error::invalid(path, format!("not a safetensors file: {e}")))?;
    let metadata = meta.metadata().clone().unwrap_or_default();
    if let Some(problem) =
        checkpoint_version_problem(metadata.get(CHECKPOINT_VERSION_KEY).map(String::as_str))
    {
        return Err(Error::invalid(path, problem));
    }
    if let Some(kind) = metadata.get("kind")
        && kind != expected
    {
        return Err(Error::invalid(
            path,
            format!("holds a {kind}, not a {expected}"),
        ));
    }
    let step = match metadata.get("step") {
        Some(s) => s
            .parse()
            .map_err(|_| Error::invalid(path, format!("metadata step `{s}` is not a number")))?,
        None => 0,
    };
    let tensors = safetensors::SafeTensors::deserialize(bytes)
        .map_err(|e| Error::invalid(path, format!("unreadable tensors: {e}")))?;
    let mut weights = HashMap::new();
    for (name, view) in tensors.iter() {
        if view.dtype() != safetensors::Dtype::F32 {
            return Err(Error::invalid(
                path,
                format!("tensor `{name}` is {:?}, expected F32", view.dtype()),
            ));
        }
        let data: Vec<f32> = view
            .data()
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        if let Some(i) = data.iter().position(|v| !v.is_finite()) {
            return Err(Error::invalid(
                path,
                format!(
                    "weight `{name}` holds {} at index {i}: a diverged run cannot be exported",
                    data[i]
                ),
            ));
        }
        weights.insert(
            name.to_string(),
            Weight {
                shape: view.shape().to_vec(),
                data,
            },
        );
    }
    Ok((weights, step))
}

/// The first key of a student's shape (under `model`, and under `model.audio`) that the
/// stored `model` lacks: the trainer writes every key, so a missing one is a damaged or
/// foreign file, not a default to fill in.
fn missing_key(model: &serde_json::Value) -> Option<String> {
    let full = serde_json::to_value(StudentConfig::default()).ok()?;
    let keys = |v: &serde_json::Value| -> Vec<String> {
        v.as_object()
            .map(|o| o.keys().cloned().collect())
            .unwrap_or_default()
    };
    for key in keys(&full) {
        if model.get(&key).is_none() {
            return Some(format!("model.{key}"));
        }
    }
    for key in keys(&full["audio"]) {
        if model["audio"].get(&key).is_none() {
            return Some(format!("model.audio.{key}"));
        }
    }
    None
}
