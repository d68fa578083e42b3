//! nldf-pipeline: the jobs that cross stages, which no single stage's crate may hold without
//! depending on a sibling. It sits above nldf-train, nldf-export and nldf-infer and below
//! nldf-bench and the command line.
//!
//! [`demo`] is `nldf demo` and `nldf train --data`: the synthetic scene, the teacher and
//! the student (nldf-train's jobs, by nldf-train's recipe), the ONNX export (nldf-export)
//! and the evaluation, with progress events; [`demo_video`] its video, the exported
//! student speaking at the held-out poses (nldf-infer). [`quantize`] writes int8 models
//! (`nldf export --int8`): calibrating them means running the student's f32 graph in tract
//! (a runtime, as in nldf-infer) and then writing the int8 graph with nldf-export, which
//! never depends on a runtime.

pub mod demo;
pub mod demo_video;
pub mod error;
pub mod quantize;

pub use error::{Error, Result};
