//! Checkpoints: the weights (`model.safetensors`), the optimizer state
//! (`train_state.safetensors`) and the resolved `config.json`, each written atomically
//! (temporary file, then rename). Both safetensors files carry the step in their metadata so
//! that a resume can tell they belong together.

use std::collections::HashMap;
use std::path::Path;

use candle_core::{Device, Tensor};
use candle_nn::VarMap;
use nldf_core::files::write_atomic;
use serde::Serialize;

use crate::error::{Error, Result};
use crate::nn::sorted_vars;

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
