//! The error type of nldf-bench. The crates' own errors pass through unchanged, so that a
//! benchmark fails with the same message as the stage it ran.

/// Errors from running a benchmark and writing its report.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Reading or writing a file failed, or a file's content is wrong.
    #[error(transparent)]
    Core(#[from] nldf_core::Error),
    /// Loading data, training, evaluating or plotting failed.
    #[error(transparent)]
    Train(#[from] nldf_train::Error),
    /// Exporting a student failed.
    #[error(transparent)]
    Export(#[from] nldf_export::Error),
    /// Reading an exported model failed.
    #[error(transparent)]
    Model(#[from] nldf_model::Error),
    /// Loading a model in its runtime or rendering with it failed.
    #[error(transparent)]
    Infer(#[from] nldf_infer::Error),
    /// Calibrating and writing an int8 model failed.
    #[error(transparent)]
    Pipeline(#[from] nldf_pipeline::Error),
    /// A report could not be serialised.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// The operating system refused; `what` says what was being done.
    #[error("{what}")]
    Io {
        what: String,
        #[source]
        err: std::io::Error,
    },
    /// The run lacks what the benchmark needs (a student, a report).
    #[error("{0}")]
    Missing(String),
    /// A benchmark's setting or a timed value is out of range.
    #[error("{0}")]
    Argument(String),
    /// The machine was busier at the start than the benchmark's load limit allows.
    #[error(
        "load average {load:.2} at the start is above --max-load {max_load:.2}: wait for an \
         idle machine, or pass --force to measure anyway (the results will say so)"
    )]
    Busy { load: f64, max_load: f64 },
    /// Another error, with what was being done when it happened (`what: source` in a
    /// printed chain).
    #[error("{what}")]
    Context {
        what: String,
        #[source]
        source: Box<Error>,
    },
}

/// Result with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// An I/O error while doing `what`.
    pub fn io(what: impl Into<String>, err: std::io::Error) -> Self {
        Error::Io {
            what: what.into(),
            err,
        }
    }

    /// `self`, saying what was being done.
    pub fn context(self, what: impl Into<String>) -> Self {
        Error::Context {
            what: what.into(),
            source: Box::new(self),
        }
    }
}

/// `e` and its sources on one line, `outer: inner: ...`, as the command line prints a chain.
pub fn chain(e: &dyn std::error::Error) -> String {
    let mut line = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        line.push_str(": ");
        line.push_str(&s.to_string());
        source = s.source();
    }
    line
}

/// A temporary folder, or the error that says it could not be made.
pub(crate) fn temp_dir() -> Result<tempfile::TempDir> {
    tempfile::tempdir().map_err(|e| Error::io("creating a temporary folder", e))
}

/// Creates `dir` and its parents.
pub(crate) fn create_dir(dir: &std::path::Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(format!("creating {}", dir.display()), e))
}
