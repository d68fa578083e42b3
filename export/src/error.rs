//! The error type of nldf-export. File problems reuse nldf-core's variants, so that every
//! message names the file the same way across the workspace.

use std::path::Path;

/// Errors from exporting a student.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Reading or writing a file failed, or a checkpoint file's content is wrong.
    #[error(transparent)]
    Core(#[from] nldf_core::Error),
    /// The student cannot be exported as a frame graph.
    #[error("frame graph: {0}")]
    Frame(String),
    /// An int8 export lacks what its calibration must provide.
    #[error("int8 export: {0}")]
    Calibration(String),
}

/// Result with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// An I/O error on `path`.
    pub fn io(path: impl AsRef<Path>, err: std::io::Error) -> Self {
        Error::Core(nldf_core::Error::io(path, err))
    }

    /// A content error in `path`.
    pub fn invalid(path: impl AsRef<Path>, problem: impl Into<String>) -> Self {
        Error::Core(nldf_core::Error::invalid(path, problem))
    }
}
