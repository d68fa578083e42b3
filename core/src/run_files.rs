//! The files of a run folder, named once for the trainers that write them, the exporter that
//! reads a student back, and the command line that lists them:
//!
//! ```text
//! RUN/teacher/  config.json  model.safetensors  train_state.safetensors  log.csv
//!               training_curve.png
//! RUN/student/  the same, plus render.json, background.png, pool.safetensors and
//!               targets.safetensors
//! RUN/model.onnx
//! ```

use std::path::{Path, PathBuf};

pub use crate::render_spec::{BACKGROUND_FILE, RENDER_SPEC_FILE};

/// The teacher's folder in a run.
pub const TEACHER_DIR: &str = "teacher";
/// The default student's folder in a run (others are named by the user or the ablation).
pub const STUDENT_DIR: &str = "student";
/// Weights of a checkpoint (safetensors, the step in its metadata).
pub const MODEL_FILE: &str = "model.safetensors";
/// Optimizer state and step of a checkpoint, for bit-exact resume.
pub const STATE_FILE: &str = "train_state.safetensors";
/// The resolved configuration beside a checkpoint.
pub const CONFIG_FILE: &str = "config.json";
/// Training log, one row per logged step.
pub const LOG_FILE: &str = "log.csv";
/// Plot of the training log.
pub const CURVE_FILE: &str = "training_curve.png";
/// The teacher's cached segment colours beside a student checkpoint.
pub const TARGETS_FILE: &str = "targets.safetensors";
/// The beam pool beside a student checkpoint.
pub const POOL_FILE: &str = "pool.safetensors";
/// The exported student in a run.
pub const ONNX_FILE: &str = "model.onnx";

/// What a teacher's folder holds once trained.
pub const TEACHER_FILES: &[&str] = &[CONFIG_FILE, MODEL_FILE, STATE_FILE, LOG_FILE, CURVE_FILE];

/// What a student's folder holds once trained.
pub const STUDENT_FILES: &[&str] = &[
    CONFIG_FILE,
    RENDER_SPEC_FILE,
    BACKGROUND_FILE,
    MODEL_FILE,
    STATE_FILE,
    POOL_FILE,
    TARGETS_FILE,
    LOG_FILE,
    CURVE_FILE,
];

/// `RUN/teacher`.
pub fn teacher_dir(run: &Path) -> PathBuf {
    run.join(TEACHER_DIR)
}

/// True when `dir` holds a checkpoint (its weights file).
pub fn has_checkpoint(dir: &Path) -> bool {
    dir.join(MODEL_FILE).is_file()
}
