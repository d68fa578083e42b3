//! What trains the networks: a dataset prepared for training ([`data`]), the student's views
//! and the teacher's targets ([`views`], [`targets`]), the losses ([`loss`]), the active beam
//! pool ([`pool`]), the optimizer ([`adam`]), checkpoints and configs ([`checkpoint`],
//! [`config`], [`config_file`]), the loop every trainer shares ([`run_loop`], with its log,
//! timings, validation [`scores`] and training curves, [`plot`]) and one trainer per network ([`teacher_trainer`], [`student_trainer`],
//! [`upsampler_trainer`]), and the short-lookahead audio encoder distilled over a trained
//! student ([`lookahead`]).

pub mod adam;
pub mod checkpoint;
pub mod config;
pub mod config_file;
pub mod data;
pub mod frame_model;
pub mod log;
pub mod lookahead;
pub mod loss;
pub mod memory;
pub mod plot;
pub mod pool;
pub mod run_loop;
pub mod scores;
pub mod student_trainer;
pub mod targets;
pub mod teacher_trainer;
pub mod timing;
pub mod upsampler_trainer;
pub mod views;
