//! The synthetic talking head: a procedural head rendered by sphere tracing a signed distance
//! field, with a mouth driven by its own speech-like audio, written as an AD-NeRF dataset
//! whose ground truth (mouth opening, blink, head pose, depth) is known exactly.

pub mod head;
pub mod speech;
