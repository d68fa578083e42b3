//! Opens an exported model in the runtime a [`BackendKind`] names: tract
//! ([`TractBackend`](crate::tract_backend::TractBackend), always built) or onnxruntime (cargo
//! feature `ort`). The trait every runtime implements and its types live in
//! [`crate::runtime`], below the runtimes; they are re-exported here, so that
//! `nldf_infer::backend` names a runtime's whole interface.

use std::path::Path;

use nldf_model::ExportedModel;

#[cfg(not(feature = "ort"))]
use crate::error::Error;
use crate::error::Result;
pub use crate::runtime::{Backend, BackendKind, BackendOptions, RayOutputs, check_inputs};

/// Opens the model at `path` (checked by `nldf_model::read_model`) in the runtime `kind`.
pub fn open_backend(
    path: &Path,
    kind: BackendKind,
    options: BackendOptions,
) -> Result<Box<dyn Backend>> {
    let model = nldf_model::read_model(path)?;
    backend_for(&model, kind, options)
}

/// The runtime `kind` holding an already read model.
pub fn backend_for(
    model: &ExportedModel,
    kind: BackendKind,
    options: BackendOptions,
) -> Result<Box<dyn Backend>> {
    options.validate()?;
    match kind {
        BackendKind::Tract => Ok(Box::new(crate::tract_backend::TractBackend::new(
            model, options,
        )?)),
        BackendKind::Ort => open_ort(model, options),
    }
}

#[cfg(feature = "ort")]
fn open_ort(model: &ExportedModel, options: BackendOptions) -> Result<Box<dyn Backend>> {
    Ok(Box::new(crate::ort_backend::OrtBackend::new(
        model, options,
    )?))
}

#[cfg(not(feature = "ort"))]
fn open_ort(_model: &ExportedModel, _options: BackendOptions) -> Result<Box<dyn Backend>> {
    Err(Error::OrtLibrary(
        "this build has no onnxruntime backend: rebuild with the cargo feature `ort` \
         (e.g. `cargo build -p nldf-infer --features ort`) or use --backend tract"
            .into(),
    ))
}
