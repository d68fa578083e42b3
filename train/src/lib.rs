//! nldf-train: training with candle. The audio encoder (AD-NeRF's AudioNet and AudioAttNet),
//! the audio-conditioned NeRF teacher, the NLDF light-segment ResMLP student, their losses,
//! the active beam pool and the trainers, with safetensors checkpoints and their configs.
//! Builds on nldf-core (rays, beams, data) and nldf-kernels; nldf-export reads what it
//! writes, and nldf-pipeline's demo joins its jobs to the export. It never depends on
//! nldf-export or nldf-infer.
//!
//! Folders by concept, lowest first:
//! - [`ops`]: the fused candle ops (teacher field, student MLP) on nldf-kernels' products;
//! - [`networks`]: the networks as candle layers. The teacher follows nerfstudio's split:
//!   [`networks::sampler`] (where rays are sampled), [`networks::field`] (the network),
//!   [`networks::render`] (compositing), joined by [`networks::teacher`]; the student
//!   ([`networks::student`]), the audio encoder and the learned upsampler beside it;
//! - [`trainers`]: what trains them: data, views and targets, losses, the pool, the
//!   optimizer, checkpoints and configs, the run loop and one trainer per network;
//! - [`reports`]: evaluation, scores, plots and the training-step benchmarks;
//! - [`job`]: the training jobs the command line and the pipeline run.

pub mod error;
pub mod job;
/// The dense-layer kernels the fused ops are built on (the `nldf-kernels` crate).
pub use nldf_kernels as kernels;
pub mod networks;
pub mod ops;
pub mod reports;
pub mod trainers;

pub use error::{Error, Result};
