//! The error type of nldf-prepare: one line that names the file and what is wrong with it.

use std::path::{Path, PathBuf};

/// Errors from preparing a dataset from a video.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An error from nldf-core (reading or writing dataset files).
    #[error(transparent)]
    Core(#[from] nldf_core::Error),
    /// The operating system refused a read or write.
    #[error("{}: {err}", path.display())]
    Io { path: PathBuf, err: std::io::Error },
    /// An input (the video, a helper's output) is wrong; `problem` says what.
    #[error("{}: {problem}", path.display())]
    Invalid { path: PathBuf, problem: String },
    /// A value passed in code or on the command line is out of range, or a computation
    /// cannot go on (too few points to solve a pose, say).
    #[error("{0}")]
    Argument(String),
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

    /// A content error in `path`, on one line.
    pub fn invalid(path: impl AsRef<Path>, problem: impl Into<String>) -> Self {
        Error::Invalid {
            path: path.as_ref().to_path_buf(),
            problem: nldf_core::error::one_line(&problem.into()),
        }
    }
}
