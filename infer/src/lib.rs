//! nldf-infer: renders talking-head frames and video from an exported ONNX model on the CPU,
//! with tract (default, pure Rust) or onnxruntime (the `ort` crate, loaded at run time).
//! Builds on nldf-core for rays, beams and audio features; never depends on candle.
