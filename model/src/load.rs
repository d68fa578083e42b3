//! Reading an exported model back, with the checks every command that loads a `.onnx`
//! runs first: the file decodes as ONNX, carries nldf's metadata, and its graph has the
//! contract's inputs and outputs and complete initializers. Each failure is one line that
//! names the file.

use std::path::{Path, PathBuf};

use prost::Message;

use nldf_core::frame_audio::FrameAudio;

use crate::contract::{
    self, FRAME_INPUT_AUDIO, FRAME_INPUT_KEEP, FRAME_INPUT_POSE, FRAME_OUTPUT_IMAGE,
    FRAME_OUTPUT_RAYS, FRAME_OUTPUT_WINDOWS, MetadataError, ModelInfo,
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

/// A frame graph (`nldf export --frame`), read and checked.
#[derive(Debug, Clone)]
pub struct FrameGraphFile {
    /// Where it was read from.
    pub path: PathBuf,
    /// The file's bytes (what a runtime loads).
    pub bytes: Vec<u8>,
    /// Its metadata.
    pub info: ModelInfo,
    /// Which samples its audio input holds.
    pub audio: FrameAudio,
    /// Output pixels per coarse ray along each side with a learned upsampler (1 without):
    /// the `keep` input is the coarse grid's.
    pub upsample: usize,
}

impl FrameGraphFile {
    /// The `[height, width]` of the `keep` input: the image's, or the upsampler's coarse
    /// grid's.
    pub fn keep_shape(&self) -> [usize; 2] {
        let k = self.info.spec.intrinsics;
        let r = self.upsample.max(1);
        [k.height as usize / r, k.width as usize / r]
    }
}

/// Reads and checks the frame graph at `path`, as [`read_model`] reads a ray graph.
pub fn read_frame_model(path: &Path) -> Result<FrameGraphFile> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let proto = decode(path, &bytes)?;
    let (info, audio) = ModelInfo::from_frame_metadata(&proto.metadata_props)
        .map_err(|e| metadata_error(path, e))?;
    check_graph(
        path,
        &proto,
        &info,
        &[FRAME_INPUT_AUDIO, FRAME_INPUT_POSE, FRAME_INPUT_KEEP],
        &[FRAME_OUTPUT_IMAGE, FRAME_OUTPUT_WINDOWS, FRAME_OUTPUT_RAYS],
    )?;
    let upsample = match proto
        .metadata_props
        .iter()
        .find(|p| p.key.as_deref() == Some(crate::contract::keys::FRAME_UPSAMPLE))
        .and_then(|p| p.value.as_deref())
    {
        None => 1,
        Some(v) => v
            .parse::<usize>()
            .ok()
            .filter(|r| matches!(r, 1 | 2 | 4 | 8))
            .ok_or_else(|| {
                Error::corrupt(
                    path,
                    format!(
                        "`{}` is {v:?}, not 1, 2, 4 or 8",
                        crate::contract::keys::FRAME_UPSAMPLE
                    ),
                )
            })?,
    };
    Ok(FrameGraphFile {
        path: path.to_path_buf(),
        bytes,
        info,
        audio,
        upsample,
    })
}

fn decode(path: &Path, bytes: &[u8]) -> Result<ModelProto> {
    if bytes.is_empty() {
        return Err(Error::corrupt(path, "the file is empty"));
    }
    ModelProto::decode(bytes).map_err(|e| Error::corrupt(path, format!("protobuf: {e}")))
}

fn metadata_error(path: &Path, e: MetadataError) -> Error {
    match e {
        MetadataError::Foreign(reason) => Error::foreign(path, reason),
        MetadataError::WrongKind(reason) => Error::WrongKind {
            path: path.to_path_buf(),
            reason,
        },
        older @ MetadataError::Older(_) => Error::Older {
            path: path.to_path_buf(),
            reason: older.to_string(),
        },
        other => Error::corrupt(path, other.to_string()),
    }
}

/// The checks of [`read_model`] on bytes already read; `path` names them in errors.
pub fn check_model(path: &Path, bytes: &[u8]) -> Result<(ModelProto, ModelInfo)> {
    let proto = decode(path, bytes)?;
    let info =
        ModelInfo::from_metadata(&proto.metadata_props).map_err(|e| metadata_error(path, e))?;
    check_graph(
        path,
        &proto,
        &info,
        &contract::model_input_names(&info),
        &contract::model_output_names(&info),
    )?;
    Ok((proto, info))
}

/// The graph has the named inputs and outputs, and its initializers are whole and match
/// the checksum.
fn check_graph(
    path: &Path,
    proto: &ModelProto,
    info: &ModelInfo,
    want_inputs: &[&str],
    want_outputs: &[&str],
) -> Result<()> {
    let Some(graph) = &proto.graph else {
        return Err(Error::corrupt(path, "the model has no graph"));
    };
    let names = |v: &[crate::onnx::ValueInfoProto]| -> Vec<String> {
        v.iter().filter_map(|i| i.name.clone()).collect()
    };
    let (inputs, outputs) = (names(&graph.input), names(&graph.output));
    for &want in want_inputs {
        if !inputs.iter().any(|n| n == want) {
            return Err(Error::corrupt(
                path,
                format!("the graph lacks input `{want}` (it has {inputs:?})"),
            ));
        }
    }
    for &want in want_outputs {
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
    Ok(())
}
