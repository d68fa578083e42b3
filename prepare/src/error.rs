//! The error type of nldf-prepare: nldf-core's, whose every variant is one line that names
//! the file (the video, a helper's output) or the value at fault.

pub use nldf_core::error::{Error, Result};
