//! The training jobs run end to end through the library, as the command line runs them: a
//! tiny demo (scene, teacher, student, export, evaluation), run twice to show that the
//! second run reuses every finished stage, then a tiny ablation on its teacher.

use std::sync::atomic::AtomicBool;

use nldf_core::dataset::Split;
use nldf_core::run_files::{
    CONFIG_FILE, MODEL_FILE, ONNX_FILE, POOL_FILE, STATE_FILE, STUDENT_FILES, TARGETS_FILE,
    TEACHER_FILES,
};
use nldf_core::synth::SynthConfig;
use nldf_pipeline::demo::DemoJob;
use nldf_tests::copy_dir;
use nldf_train::job::JobEvent;
use nldf_train::job::ablation::AblationJob;
use nldf_train::job::eval::EvalJob;
use nldf_train::job::posed::PosedJob;
use nldf_train::job::student::{StudentJob, StudentSource};
use nldf_train::networks::student::StudentConfig;
use nldf_train::trainers::config::TeacherConfig;

/// `nldf demo`'s default job with its sizes and budgets shrunk; its recipe (which stages
/// run, distilled or not) stays the command line's default.
fn tiny_demo(out: &std::path::Path) -> DemoJob {
    let defaults = DemoJob::defaults(out.to_path_buf());
    DemoJob {
        scene: SynthConfig {
            seconds: 2.0,
            size: 32,
            supersample: 1,
            ..defaults.scene.clone()
        },
        teacher: TeacherConfig::tiny(),
        teacher_iters: 12,
        student: StudentConfig::tiny(),
        student_iters: 30,
        pseudo: nldf_train::job::student::PseudoSettings {
            frames: Some(6),
            rays: Some(64),
            ..defaults.pseudo
        },
        ..defaults
    }
}

#[test]
fn a_tiny_demo_and_a_tiny_ablation_run_through_the_library_jobs() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    let stop = AtomicBool::new(false);
    let mut events = Vec::new();
    let report = tiny_demo(&out)
        .run(&stop, &mut |e| events.push(e.clone()))
        .unwrap()
        .expect("the demo ran to its end");
    let stages: Vec<&String> = events
        .iter()
        .filter_map(|e| match e {
            JobEvent::Stage(s) => Some(s),
            _ => None,
        })
        .collect();
    // Scene, teacher, student, export, then `val`, `novel` and `voice`.
    assert_eq!(stages.len(), 7, "{stages:?}");
    assert!(stages[0].starts_with("synthetic scene ->"), "{stages:?}");
    assert!(stages[2].starts_with("student, distilled"), "{stages:?}");
    assert!(stages[3].starts_with("ONNX export"), "{stages:?}");
    let splits: Vec<Split> = report.splits.iter().map(|(s, _)| *s).collect();
    assert_eq!(splits, [Split::Val, Split::Novel, Split::Voice]);
    // The pinned steps are what ran, and the time breakdown names every part.
    let teacher =
        nldf_train::trainers::teacher_trainer::TeacherModel::open(&out.join("teacher")).unwrap();
    assert_eq!(teacher.step, 12);
    let timing = nldf_train::trainers::timing::Timing::open(&out).unwrap();
    let parts: Vec<&str> = timing.parts.iter().map(|p| p.what.as_str()).collect();
    for part in [
        "synthetic scene",
        "teacher: training steps",
        "student: teacher targets: recorded frames",
        "student: teacher targets: pseudo views",
        "student: training steps",
        "ONNX export",
        "evaluation: novel",
    ] {
        assert!(parts.contains(&part), "{part} not in {parts:?}");
    }
    for f in TEACHER_FILES {
        assert!(out.join("teacher").join(f).is_file(), "teacher/{f}");
    }
    // The teacher's targets exist only for a distilled student.
    let distilled = tiny_demo(&out).student_distill;
    for f in STUDENT_FILES {
        let expected = *f != TARGETS_FILE || distilled;
        assert_eq!(
            out.join("student").join(f).is_file(),
            expected,
            "student/{f}"
        );
    }
    assert_eq!(report.model.as_deref(), Some(out.join(ONNX_FILE).as_path()));
    nldf_model::read_model(&out.join(ONNX_FILE)).unwrap();
    let models: Vec<&str> = report
        .evaluation
        .models
        .iter()
        .map(|m| m.label.as_str())
        .collect();
    assert_eq!(models, ["teacher", "student"]);
    for m in &report.evaluation.models {
        assert!(
            m.psnr.is_finite() && m.psnr > 5.0,
            "{}: {}",
            m.model,
            m.psnr
        );
        assert!(!m.frames.is_empty() && m.non_finite_frames == 0);
    }
    assert!(report.eval_dir.join("grid.png").is_file());
    assert!(
        events
            .iter()
            .any(|e| matches!(e, JobEvent::TrainingEnds { stage, .. } if stage == "student"))
    );

    // The student's saved configuration is its whole recipe: trained again from
    // `student/config.json` alone, beside the demo's, it ends with the same weights.
    StudentJob {
        data: out.join("data"),
        run: out.clone(),
        name: "again".into(),
        source: StudentSource::File(out.join("student").join(CONFIG_FILE)),
        iters: None,
        minutes: None,
        resume: false,
    }
    .plan(&mut |_| {})
    .unwrap()
    .run(&stop, &mut |_| {})
    .unwrap();
    let weights = |dir: &str| {
        candle_core::safetensors::load(out.join(dir).join(MODEL_FILE), &candle_core::Device::Cpu)
            .unwrap()
    };
    let (demo, again) = (weights("student"), weights("again"));
    assert_eq!(demo.len(), again.len());
    for (name, w) in &demo {
        let a: Vec<f32> = w.flatten_all().unwrap().to_vec1().unwrap();
        let b: Vec<f32> = again[name].flatten_all().unwrap().to_vec1().unwrap();
        assert!(a == b, "{name} differs when trained again from config.json");
    }
    std::fs::remove_dir_all(out.join("again")).unwrap();

    // A second demo into the same folder reuses the scene and resumes the spent stages.
    let mut again = Vec::new();
    tiny_demo(&out)
        .run(&stop, &mut |e| again.push(e.clone()))
        .unwrap()
        .unwrap();
    assert!(
        again
            .iter()
            .any(|e| matches!(e, JobEvent::Stage(s) if s.starts_with("synthetic scene: reusing")))
    );
    assert!(
        again
            .iter()
            .any(|e| matches!(e, JobEvent::Note(s) if s.starts_with("resuming at step")))
    );

    // The ablation on the demo's teacher: distilled, pixels-only and no-pool variants
    // (tiny depth only), then the wall-time-matched pixels-only student.
    let report = AblationJob {
        data: out.join("data"),
        run: out.clone(),
        iters: 3,
        model: ("tiny".into(), StudentConfig::tiny()),
        depths: vec![("tiny".into(), StudentConfig::tiny())],
        wall_time: true,
    }
    .plan()
    .unwrap()
    .run(&stop, &mut |_| {})
    .unwrap();
    let variants: Vec<&str> = report.rows.iter().map(|r| r.table.as_str()).collect();
    assert_eq!(
        variants,
        [
            "1: distillation",
            "1: distillation",
            "2: beam pool",
            "4: equal wall time",
            "4: equal wall time"
        ]
    );
    for r in &report.rows {
        assert!(r.psnr.is_finite(), "{}: {}", r.variant, r.psnr);
    }
    assert_eq!(report.rows[0].steps, 3);
    // The no-pool variant reused the distilled variant's teacher targets.
    assert!(out.join("ablate_dtiny_nopool").join(TARGETS_FILE).is_file());
    for f in &report.files {
        assert!(f.is_file(), "{}", f.display());
    }
    assert!(
        report
            .markdown
            .contains("| 2: beam pool | depth tiny, distilled, no pool | 3 |")
    );

    // `nldf eval --split novel`: the teacher and every student on the turned, closer and
    // farther views, in one table.
    let eval = EvalJob {
        run: out.clone(),
        data: out.join("data"),
        split: Split::Novel,
        frames: Some(3),
        out: None,
        against: None,
    };
    let plan = eval.plan(&mut |_| {}).unwrap();
    assert_eq!(plan.out, out.join("eval").join("novel"));
    let evaluation = plan.run(&mut |_| {}).unwrap();
    assert!(evaluation.models.len() >= 2);
    for m in &evaluation.models {
        assert_eq!((m.split.as_str(), m.frames.len()), ("novel", 3));
        assert!(m.psnr.is_finite() && m.mouth_psnr.is_some(), "{}", m.model);
        // Each frame knows its view, and the per-view means add back up to the split's.
        let views: Vec<&str> = m.by_view.iter().map(|v| v.view.as_str()).collect();
        assert!(
            views.len() > 1
                && views
                    .iter()
                    .all(|v| v.starts_with("turned ") || ["closer", "farther"].contains(v)),
            "{views:?}"
        );
        assert_eq!(m.by_view.iter().map(|v| v.frames).sum::<usize>(), 3);
        let pooled: f64 = m
            .by_view
            .iter()
            .map(|v| v.psnr * v.frames as f64)
            .sum::<f64>()
            / 3.0;
        assert!((pooled - m.psnr).abs() < 1e-9, "{pooled} {}", m.psnr);
    }

    // A model to render is not a run to resume: with every optimizer state and beam pool
    // deleted, `nldf eval` still scores the teacher and every student, as before.
    let mut deleted = 0;
    for entry in std::fs::read_dir(&out).unwrap().flatten() {
        for file in [STATE_FILE, POOL_FILE] {
            let path = entry.path().join(file);
            if path.is_file() {
                std::fs::remove_file(&path).unwrap();
                deleted += 1;
            }
        }
    }
    assert!(deleted >= 3, "{deleted} optimizer and pool files deleted");
    let bare = EvalJob {
        out: Some(out.join("eval_bare")),
        ..eval.clone()
    }
    .plan(&mut |_| {})
    .unwrap()
    .run(&mut |_| {})
    .unwrap();
    assert_eq!(bare.models.len(), evaluation.models.len());
    for (a, b) in bare.models.iter().zip(&evaluation.models) {
        assert_eq!((&a.model, a.psnr), (&b.model, b.psnr));
    }
    scores_against_another_dataset(&out, &eval, &evaluation);

    // The posed ablation: three students at equal total wall time, scored on val, novel
    // and voice, with the pose-sweep strip.
    let report = PosedJob {
        data: out.join("data"),
        run: out.clone(),
        model: StudentConfig::tiny(),
        minutes: 0.01,
        pseudo_frames: 4,
        pose_range: 2.0,
        pseudo_rays: 16,
        frames: Some(2),
    }
    .run(&stop, &mut |_| {})
    .unwrap();
    assert_eq!(report.rows.len(), 4);
    assert!(report.rows[0].variant.starts_with("teacher"));
    for r in &report.rows {
        let splits: Vec<&str> = r.scores.iter().map(|s| s.split.as_str()).collect();
        assert_eq!(splits, ["val", "novel", "voice"], "{}", r.variant);
        assert!(r.scores.iter().all(|s| s.psnr.is_finite()), "{}", r.variant);
    }
    // The pixels-only student had the teacher's minutes on top of a distilled student's.
    let teacher_minutes = report.rows[0].own_minutes;
    let pixels = &report.rows[3];
    assert!(pixels.variant.contains("pixels only"));
    let rows: Vec<(f64, f64)> = report
        .rows
        .iter()
        .map(|r| (r.own_minutes, r.total_minutes))
        .collect();
    assert!(
        pixels.own_minutes >= teacher_minutes + report.rows[1].own_minutes - 0.01,
        "{rows:?}"
    );
    for f in &report.files {
        assert!(f.is_file(), "{}", f.display());
    }
    let strip = nldf_core::image::ImageRgb::load(&out.join("posed_sweep.png")).unwrap();
    // Ground truth and four models in rows, the seven sweep poses in columns.
    assert_eq!((strip.width, strip.height), (7 * 34 + 2, 5 * 34 + 2));
}

#[test]
fn a_tiny_demo_with_the_grid_teacher_distils_its_student_from_the_grid() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    let stop = AtomicBool::new(false);
    let mut teacher = TeacherConfig::tiny();
    teacher.depth = 2;
    teacher.skips = vec![];
    teacher.grid = Some(nldf_train::networks::hash_grid::GridConfig {
        levels: 6,
        log2_table: 10,
        max_resolution: 64,
        ..Default::default()
    });
    let job = DemoJob {
        teacher,
        teacher_lr: nldf_train::job::recipe::DEMO_GRID_TEACHER_LR,
        train_seed: 7,
        ..tiny_demo(&out)
    };
    let report = job
        .run(&stop, &mut |_| {})
        .unwrap()
        .expect("the demo ran to its end");
    let teacher =
        nldf_train::trainers::teacher_trainer::TeacherModel::open(&out.join("teacher")).unwrap();
    let grid = teacher.cfg.model.grid.as_ref().expect("a grid teacher");
    assert_eq!(
        teacher.cfg.train.lr,
        nldf_train::job::recipe::DEMO_GRID_TEACHER_LR
    );
    assert!(grid.hi.iter().zip(&grid.lo).all(|(h, l)| h > l));
    // The run's seed is in both stages' saved configs.
    assert_eq!(teacher.cfg.train.seed, 7);
    let student: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("student/config.json")).unwrap())
            .unwrap();
    assert_eq!(student["train"]["seed"], 7, "{}", student["train"]);
    let described: Vec<&str> = report
        .evaluation
        .models
        .iter()
        .map(|m| m.model.as_str())
        .collect();
    assert!(
        described[0].starts_with("grid teacher 2x32"),
        "{described:?}"
    );
    for m in &report.evaluation.models {
        assert!(
            m.psnr.is_finite() && m.psnr > 5.0,
            "{}: {}",
            m.label,
            m.psnr
        );
    }
    // A learning rate out of range is refused before any work.
    let bad = DemoJob {
        teacher_lr: 0.0,
        ..tiny_demo(&dir.path().join("bad"))
    };
    assert!(bad.run(&stop, &mut |_| {}).is_err());
    assert!(!dir.path().join("bad").exists());
}

/// `nldf eval --against`: the same renders scored against another dataset's frames of the
/// same `img_id`. Against an exact copy of the run's data the scores are the data's own;
/// against a copy whose images are darker they move; against one that lacks a frame the
/// evaluation stops, naming that dataset.
fn scores_against_another_dataset(
    out: &std::path::Path,
    eval: &EvalJob,
    own: &nldf_train::reports::eval::Evaluation,
) {
    let run = |against: &std::path::Path, name: &str| {
        EvalJob {
            out: Some(out.join(name)),
            against: Some(against.to_path_buf()),
            ..eval.clone()
        }
        .plan(&mut |_| {})
        .and_then(|plan| plan.run(&mut |_| {}))
    };
    let twin = out.join("data_twin");
    copy_dir(&out.join("data"), &twin);
    let same = run(&twin, "eval_twin").unwrap();
    for (a, b) in same.models.iter().zip(&own.models) {
        assert_eq!(
            (a.psnr, a.head_psnr, a.mouth_psnr),
            (b.psnr, b.head_psnr, b.mouth_psnr)
        );
    }
    let dark = out.join("data_dark");
    copy_dir(&out.join("data"), &dark);
    for e in std::fs::read_dir(dark.join("head_imgs")).unwrap().flatten() {
        let mut img = nldf_core::image::ImageRgb::load(&e.path()).unwrap();
        img.data.iter_mut().for_each(|v| *v *= 0.5);
        img.save_png(&e.path()).unwrap();
    }
    let darker = run(&dark, "eval_dark").unwrap();
    for (a, b) in darker.models.iter().zip(&own.models) {
        let (a, b) = (a.head_psnr.unwrap(), b.head_psnr.unwrap());
        assert!(
            (a - b).abs() > 1.0,
            "{}: {a} against the darker frames, {b} against its own",
            eval.run.display()
        );
    }
    let short = out.join("data_short");
    copy_dir(&out.join("data"), &short);
    let path = short.join("transforms_novel.json");
    let mut file: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let frames = file["frames"].as_array_mut().unwrap();
    let first = frames.remove(0)["img_id"].as_i64().unwrap();
    std::fs::write(&path, file.to_string()).unwrap();
    let err = run(&short, "eval_short").err().unwrap().to_string();
    assert!(
        err.contains(&format!("has no frame {first} in its novel split"))
            && err.contains("data_short"),
        "{err}"
    );
}
