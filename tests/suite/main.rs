//! The workspace test suite: one binary, a module per topic.

mod adnerf;
mod audio;
mod browser;
mod dataset;
mod export;
mod export_ort;
mod figures;
mod frame_graph;
mod fuzz;
mod identity;
mod infer;
mod jobs;
mod layers;
mod machine_paths;
mod metrics;
mod posed;
mod rendering;
mod shipped;
mod stress;
mod student;
mod synth;
mod synth_head;
mod teacher;
mod trust;
mod upsampler;
mod util;
