//! nldf-export: the trained student and its audio encoder as one ONNX graph, written with
//! prost message types (no protoc), plus the ONNX contract (names, shapes, opset, metadata
//! keys) that nldf-infer and the tests import. Reads checkpoints written by nldf-train.
