//! The error type of nldf-infer. Every variant renders as one line that names the file,
//! value or runtime it is about, so that `nldf render` can print it as it is.

use std::path::{Path, PathBuf};

/// Errors from loading a model, preparing a render and running a backend.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Reading or writing a file failed, or an input file's content is wrong.
    #[error(transparent)]
    Core(#[from] nldf_core::Error),
    /// The model file is not an nldf model (corrupt, truncated or foreign).
    #[error(transparent)]
    Model(#[from] nldf_model::Error),
    /// The onnxruntime library cannot be found or loaded.
    #[error("onnxruntime: {0}")]
    OrtLibrary(String),
    /// A runtime refused the model or failed while running it.
    #[error("{backend}: {message}")]
    Backend {
        backend: &'static str,
        message: String,
    },
    /// A pose file holds a pose that is not a rigid camera-to-world transform.
    #[error("{}: frame {frame}: transform_matrix {problem}", path.display())]
    Pose {
        path: PathBuf,
        frame: usize,
        problem: String,
    },
    /// The output folder cannot be used.
    #[error("{}: {problem}", path.display())]
    Output { path: PathBuf, problem: String },
    /// An argument or setting is out of range.
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

    /// A runtime failure of `backend`; the runtime's message is kept to its first line.
    pub fn backend(backend: &'static str, message: impl std::fmt::Display) -> Self {
        let message = message.to_string();
        let first = message
            .lines()
            .next()
            .unwrap_or_default()
            .trim()
            .to_string();
        Error::Backend {
            backend,
            message: first,
        }
    }

    /// An output folder problem.
    pub fn output(path: impl AsRef<Path>, problem: impl Into<String>) -> Self {
        Error::Output {
            path: path.as_ref().to_path_buf(),
            problem: problem.into(),
        }
    }
}
