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

/// The metadata key of a checkpoint's safetensors files ([`MODEL_FILE`], [`STATE_FILE`])
/// that holds its format's version.
pub const CHECKPOINT_VERSION_KEY: &str = "nldf.checkpoint";

/// The checkpoint format this build writes and reads: 2, every student with opacity and
/// anchored beams (its `config.json` without the retired `opacity` and `anchor_beams`).
/// Checkpoints without [`CHECKPOINT_VERSION_KEY`] are version 1, made before it.
pub const CHECKPOINT_VERSION: u32 = 2;

/// The one version check of a checkpoint's weights: `found` is the metadata's
/// [`CHECKPOINT_VERSION_KEY`]. Returns why the checkpoint cannot be read, if it cannot.
pub fn checkpoint_version_problem(found: Option<&str>) -> Option<String> {
    let version = match found {
        None => 1,
        Some(v) => match v.parse::<u32>() {
            Ok(v) => v,
            Err(_) => return Some(format!("its checkpoint version `{v}` is not a number")),
        },
    };
    match version.cmp(&CHECKPOINT_VERSION) {
        std::cmp::Ordering::Equal => None,
        std::cmp::Ordering::Less => Some(format!(
            "made by an older nldf (checkpoint version {version}, this build reads \
             {CHECKPOINT_VERSION}): train again or re-export"
        )),
        std::cmp::Ordering::Greater => Some(format!(
            "made by a newer nldf (checkpoint version {version}, this build reads \
             {CHECKPOINT_VERSION}): update nldf"
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_this_checkpoint_version_is_read() {
        assert_eq!(checkpoint_version_problem(Some("2")), None);
        let older = checkpoint_version_problem(None).unwrap();
        assert!(older.contains("made by an older nldf"), "{older}");
        assert!(older.contains("train again or re-export"), "{older}");
        let older = checkpoint_version_problem(Some("1")).unwrap();
        assert!(older.contains("version 1"), "{older}");
        let newer = checkpoint_version_problem(Some("3")).unwrap();
        assert!(newer.contains("newer nldf"), "{newer}");
        let bad = checkpoint_version_problem(Some("two")).unwrap();
        assert!(bad.contains("`two`"), "{bad}");
    }
}
