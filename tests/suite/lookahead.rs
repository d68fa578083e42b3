//! The short-lookahead student (`nldf train lookahead`): the encoder's distillation on a
//! real scene's audio, its folder, and the lookahead it buys a stream.

use nldf_core::audio::FeatureConfig;
use nldf_export::{WeightType, export_student};
use nldf_model::read_model;
use nldf_train::job::lookahead::LookaheadJob;
use nldf_train::networks::student::StudentConfig;
use nldf_train::trainers::config::{StudentRunConfig, read_config};
use nldf_train::trainers::lookahead::LookaheadConfig;

use crate::util::{tiny_scene, write_run};

/// Rewrites the fixture's `config.json` as the trainer writes it (`model` and `train`).
fn as_trained(student: &std::path::Path) {
    let path = student.join("config.json");
    let written: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    let config = serde_json::json!({ "model": written["model"] });
    std::fs::write(&path, config.to_string()).unwrap();
}

/// The lookahead of a window read `ahead` feature frames past its centre, at nldf's
/// defaults: the last frame read starts `ahead - 1` hops of 20 ms after the centre and
/// ends half a 25 ms window later.
#[test]
fn lookahead_of_a_window_counts_its_hops_and_half_a_hann_window() {
    let f = FeatureConfig::default();
    assert!((f.lookahead_s(8) - 0.1525).abs() < 1e-15);
    assert!((f.lookahead_s(5) - 0.0925).abs() < 1e-15);
    assert_eq!(f.ahead_within(0.1), Some(5));
    assert_eq!(f.ahead_within(0.0925), Some(5));
    assert_eq!(f.ahead_within(0.06), Some(3));
    assert_eq!(f.ahead_within(1.0), Some(8));
    assert_eq!(f.ahead_within(0.01), None);
}

/// Distilled on the tiny scene's training frames, the short encoder's codes come far closer
/// to the full encoder's than the full encoder's on the cut windows; the new folder is a
/// student whose config and exported graph say how far ahead it reads. A student with
/// attention is refused and leaves no folder; an occupied folder is refused.
#[test]
fn lookahead_distils_the_encoder_towards_the_full_codes_into_a_new_student() {
    let mut cfg = StudentConfig::tiny();
    cfg.attention = false;
    let run = write_run(&cfg, 41);
    as_trained(&run.student_dir());
    let job = LookaheadJob {
        data: tiny_scene().to_path_buf(),
        run: run.root.clone(),
        student: "student".into(),
        name: "student_lookahead".into(),
        config: LookaheadConfig {
            lookahead_ms: 60.0,
            steps: 400,
            ..LookaheadConfig::default()
        },
    };
    let mut losses = Vec::new();
    let report = job.run(&mut |_, l| losses.push(l)).unwrap();
    assert_eq!(report.ahead, 3);
    assert!((report.lookahead_ms - 52.5).abs() < 1e-9);
    assert_eq!(losses.len(), 400);
    for e in &report.code_error {
        println!(
            "{}: {} windows, code error {:.4} -> {:.4}",
            e.frames, e.n, e.before, e.after
        );
        assert!(e.before > 0.0 && e.after.is_finite());
    }
    let train = &report.code_error[0];
    assert_eq!(train.frames, "train");
    assert!(train.after < 0.3 * train.before, "{train:?}");
    let val = report
        .code_error
        .iter()
        .find(|e| e.frames == "val")
        .unwrap();
    assert!(val.after < val.before, "{val:?}");
    let dir = run.root.join("student_lookahead");
    let saved: StudentRunConfig = read_config(&dir.join("config.json")).unwrap();
    assert_eq!(saved.model.audio.ahead, Some(3));
    let out = run.root.join("lookahead.onnx");
    export_student(&dir, &out, WeightType::F32).unwrap();
    assert_eq!(read_model(&out).unwrap().info.audio.ahead, Some(3));
    // Occupied: refused.
    let err = job.run(&mut |_, _| {}).unwrap_err().to_string();
    assert!(err.contains("already holds files"), "{err}");
    // A student with attention: refused, no folder left.
    let with_attention = write_run(&StudentConfig::tiny(), 42);
    as_trained(&with_attention.student_dir());
    let job = LookaheadJob {
        run: with_attention.root.clone(),
        ..job
    };
    let err = job.run(&mut |_, _| {}).unwrap_err().to_string();
    assert!(err.contains("needs a student without attention"), "{err}");
    assert!(!with_attention.root.join("student_lookahead").exists());
}
