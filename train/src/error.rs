//! The error type of nldf-train. File problems reuse nldf-core's variants, so that every
//! message names the file the same way across the workspace.

use std::path::Path;

/// Errors from building, training, saving and loading models.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A tensor operation failed (a shape mismatch names the shapes).
    #[error(transparent)]
    Candle(#[from] candle_core::Error),
    /// Reading or writing a file failed, or a file's content is wrong.
    #[error(transparent)]
    Core(#[from] nldf_core::Error),
    /// A setting is out of range.
    #[error("{0}")]
    Config(String),
    /// A loss, gradient or weight became NaN or infinite: training stops rather than
    /// checkpoint or export it.
    #[error("{0}")]
    NonFinite(String),
    /// Another error, with what was being done when it happened.
    #[error("{what}: {source}")]
    Context { what: String, source: Box<Error> },
}

/// Result with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// `self`, saying what was being done: `what: self`.
    pub fn context(self, what: impl Into<String>) -> Self {
        Error::Context {
            what: what.into(),
            source: Box::new(self),
        }
    }

    /// An I/O error on `path`.
    pub fn io(path: impl AsRef<Path>, err: std::io::Error) -> Self {
        Error::Core(nldf_core::Error::io(path, err))
    }

    /// A content error in `path`.
    pub fn invalid(path: impl AsRef<Path>, problem: impl Into<String>) -> Self {
        Error::Core(nldf_core::Error::invalid(path, problem))
    }
}
