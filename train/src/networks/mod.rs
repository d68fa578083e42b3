//! The networks as candle layers: the teacher NeRF split as nerfstudio splits it
//! ([`sampler`], [`field`], [`render`], joined by [`teacher`], shaped by
//! [`teacher_config`]) with its hash-grid encoding,
//! the student's residual MLP and segment sum ([`student`]), the audio encoder
//! ([`audio_net`]), the learned upsampler ([`upsampler`]) and the variable helpers they
//! share ([`nn`]).

pub mod audio_net;
pub mod field;
pub mod hash_grid;
pub mod hash_grid_reference;
pub mod nn;
pub mod occupancy;
pub mod render;
pub mod sampler;
pub mod student;
pub mod teacher;
pub mod teacher_config;
pub mod upsampler;
