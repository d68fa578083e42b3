//! The error type of nldf-model: why a file is not a model that nldf can load. File
//! problems reuse nldf-core's variants, so that every message names the file the same way
//! across the workspace.

use std::path::{Path, PathBuf};

/// Errors from reading an exported model.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Reading the file failed.
    #[error(transparent)]
    Core(#[from] nldf_core::Error),
    /// The file is not a readable ONNX model: cut short, damaged, or not ONNX at all.
    #[error("{}: not a readable ONNX model (corrupt or truncated?): {reason}", path.display())]
    Corrupt { path: PathBuf, reason: String },
    /// The file is an ONNX model, but not one that `nldf export` wrote.
    #[error("{}: not an nldf model ({reason}); make one with `nldf export`", path.display())]
    Foreign { path: PathBuf, reason: String },
    /// The file is an nldf model of the other kind (a frame graph where a ray graph is
    /// wanted, or the reverse).
    #[error("{}: {reason}", path.display())]
    WrongKind { path: PathBuf, reason: String },
    /// The file is an nldf model made by an older nldf, whose models this build no longer
    /// reads (the reason says "made by an older nldf ...").
    #[error("{}: {reason}", path.display())]
    Older { path: PathBuf, reason: String },
}

/// Result with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// An I/O error on `path`.
    pub fn io(path: impl AsRef<Path>, err: std::io::Error) -> Self {
        Error::Core(nldf_core::Error::io(path, err))
    }

    /// A model file that cannot be decoded or is incomplete.
    pub fn corrupt(path: impl AsRef<Path>, reason: impl Into<String>) -> Self {
        Error::Corrupt {
            path: path.as_ref().to_path_buf(),
            reason: reason.into(),
        }
    }

    /// An ONNX model that is not an nldf student.
    pub fn foreign(path: impl AsRef<Path>, reason: impl Into<String>) -> Self {
        Error::Foreign {
            path: path.as_ref().to_path_buf(),
            reason: reason.into(),
        }
    }
}
