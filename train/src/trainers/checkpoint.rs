//! Checkpoints: the weights (`model.safetensors`), the optimizer state
//! (`train_state.safetensors`) and the resolved `config.json`, each written atomically
//! (temporary file, then rename). Both safetensors files carry the step in their metadata so
//! that a resume can tell they belong together.

use std::collections::HashMap;
use std::path::Path;

use candle_core::{DType, Device, Tensor};
use candle_nn::VarMap;
use nldf_core::files::write_atomic;
use serde::Serialize;

use crate::error::{Error, Result};
use crate::networks::nn::sorted_vars;
use crate::trainers::adam::Adam;
use nldf_core::run_files::{
    CHECKPOINT_VERSION, CHECKPOINT_VERSION_KEY, CURVE_FILE, LOG_FILE, MODEL_FILE, STATE_FILE,
    checkpoint_version_problem,
};

/// Writes named tensors with string metadata to `path` atomically.
pub fn save_tensors(
    path: &Path,
    tensors: &HashMap<String, Tensor>,
    metadata: HashMap<String, String>,
) -> Result<()> {
    let mut entries: Vec<(&String, &Tensor)> = tensors.iter().collect();
    entries.sort_by(|a, b| a.0.cmp(b.0));
    let bytes = safetensors::serialize(entries, Some(metadata))
        .map_err(|e| Error::invalid(path, format!("cannot serialise tensors: {e}")))?;
    Ok(write_atomic(path, &bytes)?)
}

/// Reads a safetensors file: its tensors (f32 on the CPU) and its metadata.
pub fn load_tensors(path: &Path) -> Result<(HashMap<String, Tensor>, HashMap<String, String>)> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    parse_tensors(path, &bytes)
}

/// [`load_tensors`] on bytes already read; `path` names them in errors.
pub fn parse_tensors(
    path: &Path,
    bytes: &[u8],
) -> Result<(HashMap<String, Tensor>, HashMap<String, String>)> {
    let (_, meta) = safetensors::SafeTensors::read_metadata(bytes)
        .map_err(|e| Error::invalid(path, format!("not a safetensors file: {e}")))?;
    let metadata = meta.metadata().clone().unwrap_or_default();
    let tensors = candle_core::safetensors::load_buffer(bytes, &Device::Cpu)
        .map_err(|e| Error::invalid(path, format!("unreadable tensors: {e}")))?;
    Ok((tensors, metadata))
}

/// The weights of `varmap` as named tensors.
pub fn weights(varmap: &VarMap) -> Result<HashMap<String, Tensor>> {
    Ok(sorted_vars(varmap)?
        .into_iter()
        .map(|(k, v)| (k, v.as_tensor().clone()))
        .collect())
}

/// Sets every variable of `varmap` from `tensors`, checking names and shapes.
pub fn restore_weights(
    path: &Path,
    varmap: &VarMap,
    tensors: &HashMap<String, Tensor>,
) -> Result<()> {
    for (name, var) in sorted_vars(varmap)? {
        let t = tensors
            .get(&name)
            .ok_or_else(|| Error::invalid(path, format!("lacks weight `{name}`")))?;
        if t.dims() != var.dims() {
            return Err(Error::invalid(
                path,
                format!(
                    "weight `{name}` has shape {:?}, the model expects {:?} (was it trained with another config?)",
                    t.dims(),
                    var.dims()
                ),
            ));
        }
        var.set(&t.to_dtype(candle_core::DType::F32)?)?;
    }
    Ok(())
}

/// Writes a JSON file atomically, pretty-printed.
pub fn save_json(path: &Path, value: &impl Serialize) -> Result<()> {
    Ok(nldf_core::files::write_json(path, value)?)
}

/// The `step` entry of a checkpoint's metadata.
pub fn step_of(path: &Path, metadata: &HashMap<String, String>) -> Result<usize> {
    metadata
        .get("step")
        .and_then(|s| s.parse().ok())
        .ok_or_else(|| Error::invalid(path, "metadata lacks the training step"))
}

/// What [`save_checkpoint`] writes.
pub struct CheckpointParts<'a> {
    pub dir: &'a Path,
    /// `teacher` or `student`, in the safetensors metadata.
    pub kind: &'a str,
    pub step: usize,
    pub elapsed: f64,
    pub varmap: &'a VarMap,
    pub adam: &'a Adam,
    /// Title of the training-curve plot.
    pub title: &'a str,
}

/// Writes the optimizer state, then the weights (each atomically, with the step and the
/// checkpoint version in their metadata), and redraws the training curve from `log.csv`. The caller writes its config.
pub fn save_checkpoint(parts: &CheckpointParts) -> Result<()> {
    let dir = parts.dir;
    let weights = weights(parts.varmap)?;
    if let Some(name) = first_non_finite(&weights)? {
        return Err(Error::NonFinite(format!(
            "refusing to checkpoint {}: weight `{name}` holds a NaN or infinite value",
            dir.display()
        )));
    }
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let meta = |kind: &str| {
        [
            ("step".to_string(), parts.step.to_string()),
            ("elapsed_s".to_string(), format!("{:.3}", parts.elapsed)),
            ("kind".to_string(), kind.to_string()),
            (
                CHECKPOINT_VERSION_KEY.to_string(),
                CHECKPOINT_VERSION.to_string(),
            ),
        ]
        .into_iter()
        .collect()
    };
    save_tensors(
        &dir.join(STATE_FILE),
        &parts.adam.state()?,
        meta("optimizer"),
    )?;
    save_tensors(&dir.join(MODEL_FILE), &weights, meta(parts.kind))?;
    let log = dir.join(LOG_FILE);
    if log.is_file() {
        let rows = crate::trainers::log::read_log(&log)?;
        crate::trainers::plot::plot_training_curve(&dir.join(CURVE_FILE), parts.title, &rows)?;
    }
    Ok(())
}

/// The name of the first tensor (in name order) holding a NaN or infinite value.
pub fn first_non_finite(tensors: &HashMap<String, Tensor>) -> Result<Option<String>> {
    let mut names: Vec<&String> = tensors.keys().collect();
    names.sort();
    for name in names {
        let values: Vec<f32> = tensors[name]
            .flatten_all()?
            .to_dtype(DType::F32)?
            .to_vec1()?;
        if values.iter().any(|v| !v.is_finite()) {
            return Ok(Some(name.clone()));
        }
    }
    Ok(None)
}

/// Training time across resumes: the seconds of the earlier processes (from the
/// checkpoint) plus this one's.
#[derive(Debug, Clone, Copy)]
pub struct Clock {
    before: f64,
    /// When it started running; `None` for a stopped clock.
    started: Option<std::time::Instant>,
}

impl Clock {
    /// A clock that has run `before` seconds in earlier processes, running from now.
    pub fn resumed(before: f64) -> Clock {
        Clock {
            before,
            started: Some(std::time::Instant::now()),
        }
    }

    /// A clock stopped at `before` seconds: that of a run opened to render or score, whose
    /// training time must not grow while it waits.
    pub fn stopped(before: f64) -> Clock {
        Clock {
            before,
            started: None,
        }
    }

    /// Training seconds so far.
    pub fn elapsed(&self) -> f64 {
        self.before + self.started.map_or(0.0, |s| s.elapsed().as_secs_f64())
    }
}

/// Restores the weights in `dir` into `varmap` and, given `adam`, the optimizer state
/// (checking the checkpoint's version first, then that both come from the same step). Returns the step and the training clock.
pub fn open_checkpoint(
    dir: &Path,
    varmap: &VarMap,
    adam: Option<&mut Adam>,
) -> Result<(usize, Clock)> {
    let model_path = dir.join(MODEL_FILE);
    let (tensors, meta) = load_tensors(&model_path)?;
    if let Some(problem) =
        checkpoint_version_problem(meta.get(CHECKPOINT_VERSION_KEY).map(String::as_str))
    {
        return Err(Error::invalid(&model_path, problem));
    }
    restore_weights(&model_path, varmap, &tensors)?;
    let step = step_of(&model_path, &meta)?;
    let elapsed = meta
        .get("elapsed_s")
        .and_then(|s| s.parse().ok())
        .unwrap_or(0.0);
    // A run opened with its optimizer resumes training: its clock runs from now.
    let clock = if adam.is_some() {
        Clock::resumed(elapsed)
    } else {
        Clock::stopped(elapsed)
    };
    if let Some(adam) = adam {
        let state_path = dir.join(STATE_FILE);
        let (state, state_meta) = load_tensors(&state_path)?;
        let state_step = step_of(&state_path, &state_meta)?;
        if state_step != step {
            return Err(Error::invalid(
                &state_path,
                format!(
                    "is from step {state_step} but {MODEL_FILE} from step {step}; the last checkpoint was cut short"
                ),
            ));
        }
        adam.load_state(&state)
            .map_err(|e| Error::invalid(&state_path, e.to_string()))?;
    }
    Ok((step, clock))
}
