//! nldf-infer: renders talking-head frames and video from an exported ONNX model on the CPU,
//! with tract (default, pure Rust) or onnxruntime (the `ort` crate, loaded at run time).
//! Builds on nldf-core for rays, bounds and audio features and on nldf-model for the ONNX
//! contract and the checked model loaders. Never depends on candle, nor on nldf-export:
//! writing int8 models, which runs a model to calibrate it, is nldf-pipeline's job.
//!
//! [`runtime`] is the network behind one trait ([`tract_backend`], [`ort_backend`] with the
//! `ort` feature, the library found by [`ort_library`]), and [`backend`] opens a model in
//! the runtime asked for; [`frame`] renders one frame from a
//! pose and an audio neighbourhood, sending only the rays that meet the head's bounds
//! through the network; [`audio`] and [`poses`] make each frame's inputs; [`video`] renders
//! a whole WAV into PNG frames and an MP4, written through a staging folder ([`output`]);
//! [`still`] re-renders only the pixels the audio moves while the pose holds still;
//! [`stream`] renders audio that is still arriving, with bounded latency.

pub mod audio;
pub mod backend;
#[cfg(feature = "ort")]
pub mod bench;
pub mod doctor;
pub mod error;
pub mod frame;
pub mod frame_graph;
#[cfg(feature = "ort")]
pub mod ort_backend;
pub mod ort_library;
pub mod output;
pub mod poses;
pub mod runtime;
pub mod still;
pub mod stream;
pub mod tract_backend;
pub mod video;

pub use backend::{backend_for, open_backend};
pub use error::{Error, Result};
pub use frame::{FrameRenderer, RenderedFrame};
pub use runtime::{
    Backend, BackendKind, BackendOptions, BoxInput, BoxOutputs, PatchRays, RayOutputs,
};
pub use video::{VideoJob, VideoPlan, VideoReport};
