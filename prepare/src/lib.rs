//! `nldf prepare`: a video of one person speaking turned into an AD-NeRF dataset on a CPU.
//!
//! The stages, each a module:
//! - [`video`]: ffmpeg finds the streams, refuses what cannot be trained on, decodes the
//!   frames at a fixed rate and size, and the audio at 16 kHz;
//! - [`face`]: mediapipe's face landmarker (468 points), selfie segmentation and feature
//!   tracks on the head (OpenCV's Lucas-Kanade), run by a pinned Python helper in its own
//!   environment;
//! - [`pose`]: head pose without a 3DMM: PnP of the landmarks against mediapipe's canonical
//!   face, a bundle step that refines the face's shape across frames, then a robust bundle of
//!   feature tracks on the rigid head started from it, temporal smoothing, AD-NeRF's
//!   convention (head at the origin, the camera moving, OpenGL axes);
//! - [`align`]: the similarity that maps one camera track onto another, and the errors left
//!   after it (to compare a prepared dataset with the truth of a synthetic one);
//! - [`resample`]: a dataset analysed at one size written out at a smaller one (landmarks
//!   and tracks are finer in larger frames);
//! - [`check`]: a prepared dataset scored against the synthetic scene it was made from.

pub mod align;
pub mod check;
pub mod error;
pub mod face;
pub(crate) mod frames;
pub mod held_out;
pub mod job;
pub mod lms68;
pub mod parsing;
pub mod pose;
mod pose_stage;
pub(crate) mod recording;
pub mod resample;
pub(crate) mod scratch;
mod settings;
pub mod tools;
pub(crate) mod transforms;
pub mod video;

pub use error::{Error, Result};
