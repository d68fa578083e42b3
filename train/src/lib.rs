//! nldf-train: training with candle. The audio encoder (AD-NeRF's AudioNet and AudioAttNet),
//! the audio-conditioned NeRF teacher, the NLDF light-segment ResMLP student, their losses,
//! the active beam pool and the trainers, with safetensors checkpoints and their configs.
//! Builds on nldf-core (rays, beams, data) and nldf-kernels; nldf-export reads what it
//! writes, and nldf-pipeline's demo joins its jobs to the export. It never depends on
//! nldf-export or nldf-infer.
//!
//! The teacher follows nerfstudio's split: [`sampler`] (where rays are sampled), [`field`]
//! (the network), [`render`] (compositing), joined by [`teacher`] and trained by
//! [`trainer`].

pub mod adam;
pub mod audio_net;
pub mod bench;
pub mod checkpoint;
pub mod config;
pub mod config_file;
pub mod data;
pub mod error;
pub mod eval;
pub mod field;
pub mod field_op;
pub mod hash_grid;
pub mod hash_grid_reference;
pub mod job;
/// The dense-layer kernels the fused ops are built on (the `nldf-kernels` crate).
pub use nldf_kernels as kernels;
pub mod log;
pub mod loss;
pub mod memory;
pub mod nn;
pub mod op_base;
pub mod plot;
pub mod pool;
pub mod render;
pub mod run_loop;
pub mod sampler;
pub mod scores;
pub mod student;
pub mod student_op;
pub mod student_trainer;
pub mod targets;
pub mod teacher;
pub mod teacher_trainer;
pub mod timing;
pub mod upsampler;
pub mod upsampler_trainer;
pub mod views;

pub use error::{Error, Result};
