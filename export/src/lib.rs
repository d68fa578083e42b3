//! nldf-export: the trained student and its audio encoder as one ONNX graph, written with
//! the message types of nldf-model by the contract that nldf-model defines (names, shapes,
//! opset, metadata keys), so that nldf-infer and the tests read what it writes through
//! nldf-model alone. Reads checkpoints written by nldf-train with the `safetensors` crate;
//! it never depends on candle.
//!
//! [`graph`] holds a small builder, [`checkpoint`] reads `RUN/student/`, [`student`] builds
//! and writes the ray graph ([`export_student`]), [`frame`] the frame graph and
//! [`upsampler_graph`] the learned upsampler in either.

pub mod checkpoint;
pub mod error;
pub mod frame;
pub mod graph;
pub(crate) mod layers;
pub(crate) mod patch;
pub mod student;
pub mod upsampled_rays;
pub mod upsampler_graph;

pub use error::{Error, Result};
pub use frame::{
    export_frame, export_frame_int8, export_frame_upsampled, export_frame_upsampled_int8,
};
pub use graph::{ActivationRanges, Tap, WeightType};
pub use student::{ExportReport, calibration_model, export_student, export_student_int8};
pub use upsampled_rays::{export_student_upsampled, export_student_upsampled_int8};
