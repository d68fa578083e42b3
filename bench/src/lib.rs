//! nldf-bench: the benchmarks as a library. Each benchmark is a job that measures and
//! returns a typed report, and the report writes its JSON, Markdown and plots, recording
//! the machine it ran on; the `nldf bench` command line only turns flags into jobs and
//! prints what was written. Sits above nldf-train (training steps, the teacher, evaluation,
//! plots), nldf-export (the students' exports) and nldf-infer (tract and onnxruntime), since
//! the frontier puts all of them side by side.
//!
//! [`step`] times training steps, [`encoding`] the positional encoding, [`render`] whole
//! frames in both runtimes, [`stream`] a live stream's latency, [`still`] re-rendering only
//! the pixels the audio moves, and [`frontier`] run time against error for a whole run;
//! [`report`] writes the files they share. Every speed ratio comes from interleaved repeats
//! ([`repeats`]: the median and spread of per-pair ratios, "no difference" where the spread
//! reaches 1.0), and every benchmark records the machine's load before and after, refusing
//! to run on a busy machine unless forced ([`load`]).

pub mod encoding;
pub mod error;
pub mod frontier;
pub mod load;
pub mod render;
pub mod repeats;
pub mod report;
pub mod step;
pub mod still;
pub mod stream;
pub mod web;

pub use error::{Error, Result};
pub use report::Written;
