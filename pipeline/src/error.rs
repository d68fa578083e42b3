//! The error type of nldf-pipeline. The stages' own errors pass through unchanged, so that a
//! job fails with the same message as the stage it ran.

use std::path::Path;

/// Errors from a job that crosses stages.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Reading or writing a file failed, or an input file's content is wrong.
    #[error(transparent)]
    Core(#[from] nldf_core::Error),
    /// The model file is not an nldf model (corrupt, truncated or foreign).
    #[error(transparent)]
    Model(#[from] nldf_model::Error),
    /// Loading data, training or evaluating failed.
    #[error(transparent)]
    Train(#[from] nldf_train::Error),
    /// Writing a model failed.
    #[error(transparent)]
    Export(#[from] nldf_export::Error),
    /// A runtime refused the model or failed while running it.
    #[error(transparent)]
    Infer(#[from] nldf_infer::Error),
    /// An argument or setting is out of range, or the data do not fit the model; or a job's
    /// worker thread panicked.
    #[error("{0}")]
    Argument(String),
}

/// Result with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// An I/O error on `path`.
    pub fn io(path: impl AsRef<Path>, err: std::io::Error) -> Self {
        Error::Core(nldf_core::Error::io(path, err))
    }
}
