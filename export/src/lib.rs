//! nldf-export: the trained student and its audio encoder as one ONNX graph, written with
//! prost message types (no protoc), plus the ONNX contract (names, shapes, opset, metadata
//! keys) that nldf-infer and the tests import. Reads checkpoints written by nldf-train with
//! the `safetensors` crate; it never depends on candle.
//!
//! [`onnx`] holds the message types, [`graph`] a small builder, [`contract`] the one source
//! of truth for the model's interface, [`checkpoint`] reads `RUN/student/`, [`student`]
//! builds and writes the graph ([`export_student`]) and [`load`] reads a model back with
//! clear errors ([`read_model`]).

pub mod checkpoint;
pub mod contract;
pub mod error;
pub mod frame;
pub mod graph;
pub(crate) mod layers;
pub mod load;
pub mod onnx;
pub mod student;
pub mod upsampler_graph;

pub use error::{Error, Result};
pub use frame::{
    export_frame, export_frame_int8, export_frame_upsampled, export_frame_upsampled_int8,
};
pub use graph::{ActivationRanges, Tap, WeightType};
pub use load::{ExportedModel, FrameGraphFile, read_frame_model, read_model};
pub use student::{ExportReport, calibration_model, export_student, export_student_int8};
pub use upsampler_graph::{export_student_upsampled, export_student_upsampled_int8};
