//! Reading an exported model back, with the checks every command that loads a `.onnx`
//! runs first: the file decodes as ONNX, carries nldf's metadata, and its graph has the
//! contract's inputs and outputs and complete initializers. Each failure is one line that
//! names the file.

use std::path::{Path, PathBuf};

use prost::Message;

use crate::contract::{
    self, INPUT_AUDIO, INPUT_DIRECTIONS, INPUT_ORIGINS, MetadataError, ModelInfo, OUTPUT_RGB,
    OUTPUT_SEGMENTS,
};
use crate::error::{Error, Result};
use crate::onnx::{DataType, ModelProto};

/// An exported model, read and checked.
#[derive(Debug, Clone)]
pub struct ExportedModel {
    /// Where it was read from.
    pub path: PathBuf,
    /// The file's bytes (what a runtime loads).
    pub bytes: Vec<u8>,
    /// The decoded model.
    pub proto: ModelProto,
    /// Its metadata.
    pub info: ModelInfo,
}

/// Reads and checks the model at `path`: [`Error::Corrupt`] for a file that does not decode
/// or is incomplete, [`Error::Foreign`] for an ONNX model that nldf did not write.
pub fn read_model(path: &Path) -> Result<ExportedModel> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let (proto, info) = check_model(path, &bytes)?;
    Ok(ExportedModel {
        path: path.to_path_buf(),
        bytes,
        proto,
        info,
    })
}

/// The checks of [`read_model`] on bytes already read; `path` names them in errors.
pub fn check_model(path: &Path, bytes: &[u8]) -> Result<(ModelProto, ModelInfo)> {
    if bytes.is_empty() {
        return Err(Error::corrupt(path, "the file is empty"));
    }
    let proto =
        ModelProto::decode(bytes).map_err(|e| Error::corrupt(path, format!("protobuf: {e}")))?;
    let Some(graph) = &proto.graph else {
        return Err(Error::corrupt(path, "the model has no graph"));
    };
    let info = ModelInfo::from_metadata(&proto.metadata_props).map_err(|e| match e {
        MetadataError::Foreign(reason) => Error::foreign(path, reason),
        other => Error::corrupt(path, other.to_string()),
    })?;
    let names = |v: &[crate::onnx::ValueInfoProto]| -> Vec<String> {
        v.iter().filter_map(|i| i.name.clone()).collect()
    };
    let (inputs, outputs) = (names(&graph.input), names(&graph.output));
    for want in [INPUT_ORIGINS, INPUT_DIRECTIONS, INPUT_AUDIO] {
        if !inputs.iter().any(|n| n == want) {
            return Err(Error::corrupt(
                path,
                format!("the graph lacks input `{want}` (it has {inputs:?})"),
            ));
        }
    }
    for want in [OUTPUT_RGB, OUTPUT_SEGMENTS] {
        if !outputs.iter().any(|n| n == want) {
            return Err(Error::corrupt(
                path,
                format!("the graph lacks output `{want}` (it has {outputs:?})"),
            ));
        }
    }
    if contract::weights_checksum(graph) != info.weights_checksum {
        return Err(Error::corrupt(
            path,
            "the weights do not match their checksum (damaged after export)",
        ));
    }
    for t in &graph.initializer {
        let n = t.dims.iter().try_fold(
            1i64,
            |acc, &d| if d < 0 { None } else { acc.checked_mul(d) },
        );
        let elem = match t.data_type.and_then(|d| DataType::try_from(d).ok()) {
            Some(DataType::Float | DataType::Int32) => 4,
            Some(DataType::Int64 | DataType::Double) => 8,
            Some(DataType::Float16 | DataType::Int16 | DataType::Uint16) => 2,
            Some(DataType::Uint8 | DataType::Int8 | DataType::Bool) => 1,
            _ => continue,
        };
        if let Some(raw) = &t.raw_data
            && n.and_then(|n| n.checked_mul(elem)) != Some(raw.len() as i64)
        {
            return Err(Error::corrupt(
                path,
                format!(
                    "initializer `{}` holds {} bytes, which its shape {:?} does not fit",
                    t.name.as_deref().unwrap_or("?"),
                    raw.len(),
                    t.dims
                ),
            ));
        }
    }
    Ok((proto, info))
}
