//! Signed-distance head model and its sphere-tracing renderer.
