//! nldf-model: what an exported nldf model is, for every crate that writes or reads one. It
//! holds the ONNX message types (prost derives, no protoc), the contract (input and output
//! names, shapes, opset, metadata keys, the model's info: the one source of truth) and the
//! loaders that read a model back with clear errors. nldf-export writes models by it;
//! nldf-infer, the benchmarks and the tests read them by it. It needs only nldf-core: never
//! candle, tract or onnxruntime, and no crate of nldf's above core.
//!
//! [`onnx`] holds the message types, [`contract`] the model's interface, [`load`] the
//! checked readers ([`read_model`] for a ray graph, [`read_frame_model`] for a frame
//! graph) and [`error`] why a file is not a model nldf can load.

pub mod contract;
pub mod error;
pub mod load;
pub mod onnx;

pub use error::{Error, Result};
pub use load::{ExportedModel, FrameGraphFile, read_frame_model, read_model};
