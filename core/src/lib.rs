//! nldf-core: everything the talking-head pipeline shares that needs no ML framework.
//!
//! Cameras and rays in AD-NeRF's convention ([`camera`], [`rays`]), the student's beam
//! encoding ([`encoding`], [`beam`]), the f64 compositing reference of the paper's Eq. 3-5
//! ([`composite`]), datasets in AD-NeRF's layout ([`dataset`]), audio features
//! ([`audio`]), image metrics ([`metrics`]), the
//! rules training and rendering share (the student's shape in [`student_config`], the rays that
//! meet the head in [`rays::head_rays`], a frame's audio neighbourhood in
//! [`audio::neighbourhood`], the run folder's files in [`run_files`]) and a procedural talking head whose ground truth is
//! known exactly ([`synth`]). `nldf-train` (candle), `nldf-model` and `nldf-export` (prost)
//! and `nldf-infer` (tract / onnxruntime) build on it; it never depends on them.

pub mod audio;
pub mod audio_stream;
pub mod beam;
pub mod bounds;
pub mod camera;
pub mod checks;
pub mod composite;
pub mod dataset;
pub mod encoding;
pub mod error;
pub mod files;
pub mod frame_audio;
pub mod host;
pub mod image;
pub mod landmarks;
pub mod metrics;
pub mod npy;
pub mod rays;
pub mod region;
pub mod render_spec;
pub mod run_files;
pub mod stats;
pub mod student_config;
pub mod student_network;
pub mod synth;
pub mod upsampler_config;
pub mod wav;
pub mod wav_stream;

pub use error::{Error, Result};
