//! The error type of nldf-pipeline. The stages' own errors pass through unchanged, so that a
//! job fails with the same message as the stage it ran.

/// Errors from a job that crosses stages.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Reading or writing a file failed, or an input file's content is wrong.
    #[error(transparent)]
    Core(#[from] nldf_core::Error),
    /// The model file is not an nldf model (corrupt, truncated or foreign).
    #[error(transparent)]
    Model(#[from] nldf_model::Error),
    /// Writing a model failed.
    #[error(transparent)]
    Export(#[from] nldf_export::Error),
    /// A runtime refused the model or failed while running it.
    #[error(transparent)]
    Infer(#[from] nldf_infer::Error),
    /// An argument or setting is out of range, or the data do not fit the model.
    #[error("{0}")]
    Argument(String),
}

/// Result with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
