//! The error type of nldf-train.

use std::path::{Path, PathBuf};

/// Errors from building, training, saving and loading models.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A tensor operation failed (a shape mismatch names the shapes).
    #[error(transparent)]
    Candle(#[from] candle_core::Error),
    /// Reading the dataset or another nldf-core file failed.
    #[error(transparent)]
    Core(#[from] nldf_core::Error),
    /// The operating system refused a read or write.
    #[error("{}: {err}", path.display())]
    Io { path: PathBuf, err: std::io::Error },
    /// A file exists but its content is wrong.
    #[error("{}: {problem}", path.display())]
    Invalid { path: PathBuf, problem: String },
    /// A setting is out of range.
    #[error("{0}")]
    Config(String),
}

/// Result with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// An I/O error on `path`.
    pub fn io(path: impl AsRef<Path>, err: std::io::Error) -> Self {
        Error::Io {
            path: path.as_ref().to_path_buf(),
            err,
        }
    }

    /// A content error in `path`.
    pub fn invalid(path: impl AsRef<Path>, problem: impl Into<String>) -> Self {
        Error::Invalid {
            path: path.as_ref().to_path_buf(),
            problem: problem.into(),
        }
    }
}
