//! Every number nldf prints can be trusted: a NaN never scores as a perfect frame, a run
//! that diverges stops before it checkpoints or exports a NaN, a config's unknown or
//! out-of-range key is named, tract binds the graph's inputs by name, and a model trained
//! on another front end's audio features refuses a WAV.

use std::path::Path;
use std::sync::atomic::AtomicBool;

use crate::util::{
    max_diff, random_audio, random_rays, tiny_run_config, tiny_scene, write_run, write_test_wav,
};
use candle_core::{Device, Tensor};
use nldf_core::dataset::Split;
use nldf_core::image::ImageRgb;
use nldf_core::region::Region;
use nldf_export::WeightType;
use nldf_infer::backend::{BackendKind, BackendOptions, backend_for};
use nldf_model::onnx::ModelProto;
use nldf_model::read_model;
use nldf_train::networks::student::StudentConfig;
use nldf_train::reports::eval::{FrameModel, eval_models};
use nldf_train::trainers::checkpoint::save_tensors;
use nldf_train::trainers::config::{RunConfig, StudentRunConfig, TeacherRunConfig, parse_checked};
use nldf_train::trainers::data::TrainData;
use nldf_train::trainers::run_loop::{Event, Schedule, TrainingRun, train_loop};
use nldf_train::trainers::scores::{Scores, score_frames};
use nldf_train::trainers::teacher_trainer::TeacherRun;
use prost::Message;

/// An image whose every value is NaN.
fn nan_image(width: u32, height: u32) -> ImageRgb {
    ImageRgb::filled(width, height, [f32::NAN; 3])
}

#[test]
fn a_nan_render_scores_nan_not_a_perfect_frame() {
    let truth = nldf_tests::pattern_image(16, 12, 3);
    let regions = vec![Region::Mouth; 16 * 12];
    let pairs = vec![
        (nan_image(16, 12), truth.clone(), Some(regions.clone())),
        (truth.clone(), truth.clone(), Some(regions)),
    ];
    let s: Scores = score_frames(&pairs).unwrap();
    assert!(s.psnr.is_nan(), "a NaN frame scored {} dB", s.psnr);
    assert!(s.ssim.is_nan());
    assert!(s.mouth_psnr.unwrap().is_nan() && s.head_psnr.unwrap().is_nan());
    assert_eq!((s.non_finite, s.frames), (1, 2));
    // Identical frames are capped at 100 dB, not infinity.
    let s = score_frames(&[(truth.clone(), truth, None)]).unwrap();
    assert_eq!((s.psnr, s.non_finite), (100.0, 0));
}

/// A model whose renders hold NaN.
struct NanModel;

impl FrameModel for NanModel {
    fn label(&self) -> String {
        "nan".into()
    }
    fn describe(&self) -> String {
        "a model that renders NaN".into()
    }
    fn step(&self) -> usize {
        1
    }
    fn macs_per_ray(&self) -> f64 {
        1.0
    }
    fn render_frame(
        &self,
        data: &TrainData,
        _frame: &nldf_core::dataset::Frame,
    ) -> nldf_train::Result<ImageRgb> {
        let k = data.dataset.intrinsics;
        Ok(nan_image(k.width, k.height))
    }
}

#[test]
fn eval_counts_non_finite_frames_and_never_reports_inf() {
    let data = TrainData::open(tiny_scene(), false).unwrap();
    let out = tempfile::tempdir().unwrap();
    let models: Vec<&dyn FrameModel> = vec![&NanModel];
    let e = eval_models(&models, &data, Split::Val, Some(3), out.path(), &mut || {}).unwrap();
    let r = &e.models[0];
    assert_eq!(r.non_finite_frames, 3);
    assert!(r.psnr.is_nan(), "an all-NaN model scored {} dB", r.psnr);
    assert!(r.ssim.is_nan(), "an all-NaN model scored SSIM {}", r.ssim);
    assert!(r.frames.iter().all(|f| f.psnr.is_nan()));
}

/// A run whose loss turns NaN at `nan_at`, checkpointing every step into `dir`; each step
/// takes a second of its clock, against a budget of `budget_s` (0: none).
struct Diverging {
    dir: std::path::PathBuf,
    step: usize,
    nan_at: usize,
    budget_s: f64,
    /// A wall-clock cap that only stops the run.
    cap_s: f64,
    /// Seconds spent before the first step (a student's teacher targets, say).
    spent_before: f64,
}

impl Diverging {
    /// A run that never diverges, with a time budget of `budget_s` of which `spent_before`
    /// is gone before its first step.
    fn budgeted(dir: &Path, budget_s: f64, spent_before: f64) -> Diverging {
        Diverging {
            dir: dir.to_path_buf(),
            step: 0,
            nan_at: usize::MAX,
            budget_s,
            cap_s: 0.0,
            spent_before,
        }
    }
}

impl TrainingRun for Diverging {
    fn dir(&self) -> &Path {
        &self.dir
    }
    fn step(&self) -> usize {
        self.step
    }
    fn schedule(&self) -> Schedule {
        Schedule {
            iters: 10,
            batch_rays: 1,
            log_every: 1,
            val_every: 0,
            val_frames: 1,
            checkpoint_every: 1,
            time_budget_s: self.budget_s,
            time_cap_s: self.cap_s,
        }
    }
    fn elapsed(&self) -> f64 {
        self.spent_before + self.step as f64
    }
    fn learning_rate(&self) -> f64 {
        1e-3
    }
    fn train_step(&mut self, _data: &TrainData) -> nldf_train::Result<(f64, f64)> {
        self.step += 1;
        let loss = if self.step >= self.nan_at {
            f64::NAN
        } else {
            0.1
        };
        // As the trainers do: a non-finite loss is refused before any update.
        if !loss.is_finite() {
            self.step -= 1;
            return Err(nldf_train::Error::NonFinite(format!("the loss is {loss}")));
        }
        Ok((loss, 10.0))
    }
    fn validation_scores(&self, _data: &TrainData, n: usize) -> nldf_train::Result<Scores> {
        Ok(Scores {
            psnr: 30.0,
            ssim: 0.9,
            head_psnr: None,
            head_ssim: None,
            mouth_psnr: None,
            frames: n,
            non_finite: 0,
        })
    }
    fn save(&self) -> nldf_train::Result<()> {
        Ok(())
    }
}

#[test]
fn a_nan_loss_stops_training_and_keeps_the_last_good_checkpoint() {
    let data = TrainData::open(tiny_scene(), false).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut run = Diverging {
        dir: dir.path().to_path_buf(),
        step: 0,
        nan_at: 4,
        budget_s: 0.0,
        cap_s: 0.0,
        spent_before: 0.0,
    };
    let mut checkpoints = Vec::new();
    let err = train_loop(&mut run, &data, &AtomicBool::new(false), &mut |e| {
        if let Event::Checkpoint { step, .. } = e {
            checkpoints.push(*step);
        }
    })
    .unwrap_err()
    .to_string();
    assert_eq!(
        checkpoints,
        [1, 2, 3],
        "checkpoints after the loss turned NaN"
    );
    assert!(!err.contains('\n'), "{err}");
    assert!(
        err.contains("diverged at step 4") && err.contains("NaN"),
        "{err}"
    );
    assert!(err.contains("checkpoint of step 3"), "{err}");
}

#[test]
fn a_run_stops_when_its_budget_is_spent_and_a_resumed_spent_run_trains_no_step() {
    let data = TrainData::open(tiny_scene(), false).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut run = Diverging::budgeted(dir.path(), 3.0, 0.0);
    let steps = |run: &mut Diverging| {
        let mut n = 0;
        let scores = train_loop(run, &data, &AtomicBool::new(false), &mut |e| {
            n += usize::from(matches!(e, Event::Step { .. }));
        })
        .unwrap();
        (n, scores.is_some())
    };
    // The budget ends the run after its third step, validated.
    assert_eq!(steps(&mut run), (3, true));
    assert_eq!(run.step, 3);
    // Resumed with the same budget: nothing more is trained.
    assert_eq!(steps(&mut run), (0, false));
    assert_eq!(run.step, 3);
}

/// A wall-clock cap stops a run as a budget does, but leaves the learning rate to the
/// steps: a recipe pinned in steps trains the same schedule on any machine.
#[test]
fn a_time_cap_stops_the_run_and_leaves_the_learning_rate_to_the_steps() {
    let data = TrainData::open(tiny_scene(), false).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut run = Diverging::budgeted(dir.path(), 0.0, 0.0);
    run.cap_s = 4.0;
    let mut n = 0;
    train_loop(&mut run, &data, &AtomicBool::new(false), &mut |e| {
        n += usize::from(matches!(e, Event::Step { .. }));
    })
    .unwrap();
    assert_eq!((n, run.step), (4, 4));
    let capped = nldf_train::trainers::config::StudentTrainConfig {
        lr_decay_steps: 100,
        time_cap_s: 10.0,
        ..Default::default()
    };
    let budgeted = nldf_train::trainers::config::StudentTrainConfig {
        time_budget_s: 10.0,
        time_cap_s: 0.0,
        ..capped.clone()
    };
    // Near its end the budget has decayed the rate; the cap has not touched it.
    assert_eq!(capped.learning_rate(0, 9.9), capped.lr);
    assert!(budgeted.learning_rate(0, 9.9) < 0.2 * capped.lr);
}

/// A new run whose budget is spent before its first step is still written, at step 0, so
/// that a job can open and score it.
#[test]
fn a_new_run_whose_budget_is_spent_before_its_first_step_is_still_saved() {
    let data = TrainData::open(tiny_scene(), false).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut run = Diverging::budgeted(dir.path(), 3.0, 5.0);
    let mut events = Vec::new();
    train_loop(&mut run, &data, &AtomicBool::new(false), &mut |e| {
        events.push(e.clone())
    })
    .unwrap();
    let checkpoints: Vec<usize> = events
        .iter()
        .filter_map(|e| match e {
            Event::Checkpoint { step, .. } => Some(*step),
            _ => None,
        })
        .collect();
    assert_eq!(checkpoints, vec![0]);
    assert!(!events.iter().any(|e| matches!(e, Event::Step { .. })));
}

#[test]
fn adam_refuses_a_non_finite_gradient_and_checkpoints_refuse_non_finite_weights() {
    use nldf_train::trainers::adam::{Adam, AdamParams};
    let var = candle_core::Var::from_tensor(
        &Tensor::ones(4, candle_core::DType::F32, &Device::Cpu).unwrap(),
    )
    .unwrap();
    let mut adam = Adam::new(
        vec![("w".into(), var.clone(), 1.0)],
        AdamParams {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
        },
    );
    let loss = (var.as_tensor() * f64::NAN).unwrap().sum_all().unwrap();
    let grads = loss.backward().unwrap();
    let err = adam.step(&grads, 1e-3).unwrap_err().to_string();
    assert!(err.contains("gradient of `w`"), "{err}");
    let after: Vec<f32> = var.as_tensor().to_vec1().unwrap();
    assert_eq!(after, [1.0; 4], "a refused step changed the weights");

    // A teacher whose weight holds a NaN is not checkpointed.
    let data = TrainData::load(tiny_scene()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let run = TeacherRun::create(dir.path(), tiny_run_config(5), &data).unwrap();
    let (name, var) = nldf_train::networks::nn::sorted_vars(&run.model.varmap)
        .unwrap()
        .remove(0);
    let mut values: Vec<f32> = var.as_tensor().flatten_all().unwrap().to_vec1().unwrap();
    values[0] = f32::NAN;
    var.set(&Tensor::from_vec(values, var.shape(), &Device::Cpu).unwrap())
        .unwrap();
    let err = run.save().unwrap_err().to_string();
    assert!(err.contains(&name) && err.contains("NaN"), "{err}");
    assert!(!dir.path().join("model.safetensors").exists());
}

#[test]
fn export_refuses_non_finite_weights_and_fp16_refuses_weights_beyond_its_range() {
    let cfg = StudentConfig::tiny();
    let run = write_run(&cfg, 5);
    let path = run.student_dir().join("model.safetensors");
    let (tensors, meta) = nldf_train::trainers::checkpoint::load_tensors(&path).unwrap();
    let with = |name: &str, value: f32| {
        let mut t = tensors.clone();
        let w = &t[name];
        let mut v: Vec<f32> = w.flatten_all().unwrap().to_vec1().unwrap();
        v[3] = value;
        t.insert(
            name.to_string(),
            Tensor::from_vec(v, w.shape(), &Device::Cpu).unwrap(),
        );
        save_tensors(&path, &t, meta.clone()).unwrap();
    };
    let out = run.root.join("out.onnx");
    let refused = |weights: WeightType, needle: &str| {
        let err = nldf_export::export_student(&run.student_dir(), &out, weights)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("mlp.body.0.fc1.weight") && err.contains(needle),
            "{err}"
        );
        assert!(!out.exists());
    };
    with("mlp.body.0.fc1.weight", f32::NAN);
    refused(WeightType::F32, "NaN");
    with("mlp.body.0.fc1.weight", 1e5);
    refused(WeightType::F16, "--fp16");
    // In f32 the same weight is fine.
    nldf_export::export_student(&run.student_dir(), &out, WeightType::F32).unwrap();
}

/// What reading and checking `text` as a run configuration says: the error, or "" when the
/// configuration is fine.
fn config_error<T: RunConfig>(text: &str) -> String {
    parse_checked::<T>(Path::new("cfg.json"), text)
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default()
}

#[test]
fn config_files_reject_unknown_keys_and_name_bad_values() {
    let err = config_error::<TeacherRunConfig>;
    let e = err(r#"{"width": -1, "depth": "many"}"#);
    assert!(
        e.contains("cfg.json") && e.contains("unknown field `width`"),
        "{e}"
    );
    let e = err(r#"{"model": {"depth": "many"}}"#);
    assert!(e.contains("`model.depth`"), "{e}");
    let e = err(r#"{"model": {"width": -1}}"#);
    assert!(e.contains("`model.width`") && e.contains("-1"), "{e}");
    let e = err(r#"{"model": {"widht": 64}}"#);
    assert!(
        e.contains("unknown field `widht`") && e.contains("model"),
        "{e}"
    );
    let e = err(r#"{"model": {"width": 0}}"#);
    assert!(e.contains("`model.width`") && e.contains("got 0"), "{e}");
    let e = err(r#"{"train": {"lr": -0.1}}"#);
    assert!(e.contains("`train.lr`"), "{e}");
    let e = err(r#"{"train": {"face_fraction": 1.5}}"#);
    assert!(e.contains("`train.face_fraction`"), "{e}");
    let e = err(r#"{"model": {"n_samples": 1}}"#);
    assert!(e.contains("`model.n_samples`"), "{e}");
    assert_eq!(err(r#"{"model": {"width": 64}}"#), "");
    // The grid teacher's settings.
    let e = err(r#"{"model": {"grid": {"levels": 0}}}"#);
    assert!(e.contains("`model.grid.levels`"), "{e}");
    let e = err(r#"{"model": {"grid": {"log2_table": 40}}}"#);
    assert!(e.contains("`model.grid.log2_table`"), "{e}");
    let e = err(r#"{"model": {"grid": {"base_resolution": 64, "max_resolution": 16}}}"#);
    assert!(e.contains("`model.grid.max_resolution`"), "{e}");
    let e = err(r#"{"model": {"grid": {"lo": [0, 0, 0], "hi": [1, 0, 1]}}}"#);
    assert!(e.contains("`model.grid.lo`"), "{e}");
    let e = err(r#"{"model": {"grid": {"levles": 8}}}"#);
    assert!(e.contains("unknown field `levles`"), "{e}");
    assert_eq!(err(r#"{"model": {"grid": {"levels": 8}}}"#), "");
    let student = config_error::<StudentRunConfig>;
    let e = student(r#"{"model": {"depth": 7}}"#);
    assert!(e.contains("`model.depth`"), "{e}");
    let e = student(r#"{"train": {"lamda": 0.2}}"#);
    assert!(e.contains("unknown field `lamda`"), "{e}");
    let e = student(r#"{"model": {"beam": {"points": 16}}}"#);
    assert!(e.contains("unknown field `points`"), "{e}");
    let e = student(r#"{"train": {"hard_ratio": 2}}"#);
    assert!(e.contains("`train.hard_ratio`"), "{e}");
    assert_eq!(student(r#"{"model": {"depth": 28}}"#), "");
}

/// The graph's inputs (or outputs) listed in another order: tract binds them by name, as
/// onnxruntime does, so the frame does not change.
#[test]
fn tract_binds_inputs_and_outputs_by_name() {
    let cfg = StudentConfig::tiny();
    let run = write_run(&cfg, 9);
    let path = run.export(WeightType::F32);
    let rays = random_rays(700, 2);
    let audio =
        nldf_core::audio::neighbourhood(&random_audio(&cfg, 10, 3), 4, cfg.audio.att_frames);
    let options = BackendOptions {
        batch_size: 1024,
        threads: 1,
        spin: true,
    };
    let render = |p: &Path| {
        let model = read_model(p).unwrap();
        let mut b = backend_for(&model, BackendKind::Tract, options).unwrap();
        let bg = crate::util::ray_background(rays.len());
        b.run(&rays.origins, &rays.directions, &bg, &audio).unwrap()
    };
    let want = render(&path);
    let mut proto = ModelProto::decode(&std::fs::read(&path).unwrap()[..]).unwrap();
    let graph = proto.graph.as_mut().unwrap();
    graph.input.swap(0, 1);
    graph.output.swap(0, 1);
    let swapped = run.root.join("swapped.onnx");
    std::fs::write(&swapped, proto.encode_to_vec()).unwrap();
    let got = render(&swapped);
    assert_eq!(max_diff(&got.rgb, &want.rgb), 0.0);
    assert_eq!(max_diff(&got.segments, &want.segments), 0.0);
    assert_eq!(max_diff(&got.opacity, &want.opacity), 0.0);
    assert_eq!(
        want.opacity.len(),
        rays.len(),
        "the tiny student has opacity"
    );
}

/// The tiny synthetic scene with its `aud.npy` replaced by 29-wide windows of another
/// front end (no `aud.json`; `aud.wav` kept only with `keep_wav`): an AD-NeRF dataset with
/// DeepSpeech features looks like this.
fn foreign_features_scene(dir: &Path, keep_wav: bool) -> nldf_core::audio::AudioWindows {
    use nldf_core::dataset::{AUDIO_SOURCE_FILE, AUDIO_WAV, save_audio_npy};
    nldf_tests::copy_dir(tiny_scene(), dir);
    std::fs::remove_file(dir.join(AUDIO_SOURCE_FILE)).unwrap();
    if !keep_wav {
        std::fs::remove_file(dir.join(AUDIO_WAV)).unwrap();
    }
    let n = nldf_core::dataset::load_audio_npy(&dir.join("aud.npy"))
        .unwrap()
        .n_frames;
    let cfg = StudentConfig {
        audio: nldf_train::trainers::config::AudioConfig {
            n_features: 29,
            ..Default::default()
        },
        ..StudentConfig::tiny()
    };
    let windows = random_audio(&cfg, n, 77);
    save_audio_npy(&dir.join("aud.npy"), &windows).unwrap();
    windows
}

#[test]
fn datasets_say_which_front_end_made_their_features() {
    use nldf_core::audio::FeatureSource;
    use nldf_core::dataset::{AudioChoice, Dataset};
    let dir = tempfile::tempdir().unwrap();
    // nldf's own (synth writes aud.json): read from aud.npy.
    let ours = Dataset::load(tiny_scene()).unwrap();
    assert!(matches!(ours.audio_source, FeatureSource::Nldf(_)));
    assert!(ours.audio_file.ends_with("aud.npy"));
    // Another front end's aud.npy beside aud.wav: by default nldf computes its own features
    // from aud.wav, and they equal the synth's (made from the same samples).
    let root = dir.path().join("with_wav");
    let foreign = foreign_features_scene(&root, true);
    let auto = Dataset::load(&root).unwrap();
    assert!(matches!(auto.audio_source, FeatureSource::Nldf(_)));
    assert!(auto.audio_file.ends_with("aud.wav"));
    assert_eq!(auto.audio, ours.audio);
    let npy = Dataset::load_with(&root, &AudioChoice::Npy).unwrap();
    assert!(matches!(npy.audio_source, FeatureSource::Foreign { .. }));
    assert_eq!(npy.audio, foreign);
    // Without aud.wav, aud.npy is all there is: foreign.
    let root = dir.path().join("no_wav");
    foreign_features_scene(&root, false);
    let only = Dataset::load(&root).unwrap();
    assert!(matches!(
        only.audio_source,
        FeatureSource::Foreign { n_features: 29, .. }
    ));
    // A run trained on nldf's features cannot read this dataset's audio.
    let err = Dataset::load_with(&root, &AudioChoice::Matching(ours.audio_source.clone()))
        .unwrap_err()
        .to_string();
    assert!(err.contains("aud.wav") && err.contains("missing"), "{err}");
}

/// The must-show of the audio provenance: a model trained on a dataset's foreign 29-wide
/// features refuses a WAV with one clear line, and renders from `--features` exactly what
/// the candle student renders from those windows.
#[test]
fn a_model_on_foreign_features_refuses_a_wav_and_renders_from_them() {
    use nldf_infer::poses::default_track;
    use nldf_infer::video::VideoJob;
    use nldf_train::trainers::student_trainer::StudentRun;
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("scene");
    foreign_features_scene(&root, false);
    let data = TrainData::load(&root).unwrap();
    let mut cfg = StudentRunConfig {
        model: StudentConfig::tiny(),
        ..StudentRunConfig::default()
    };
    cfg.train.distill = false;
    cfg.train.batch_rays = 256;
    cfg.train.iters = 3;
    let run_dir = dir.path().join("run/student");
    let mut run = StudentRun::create(&run_dir, cfg, &data, None).unwrap();
    run.prepare(&data, None, &mut |_, _| {}).unwrap();
    for _ in 0..3 {
        run.train_step(&data).unwrap();
    }
    run.save().unwrap();
    let model = dir.path().join("run/model.onnx");
    nldf_export::export_student(&run_dir, &model, WeightType::F32).unwrap();
    let wav = dir.path().join("speech.wav");
    write_test_wav(&wav, 0.5);
    let job = |audio: Option<&Path>, features: Option<&Path>, out: &str| VideoJob {
        model: model.clone(),
        audio: audio.map(Path::to_path_buf),
        features: features.map(Path::to_path_buf),
        poses: None,
        out: dir.path().join(out),
        backend: BackendKind::Tract,
        options: BackendOptions {
            batch_size: 512,
            threads: 1,
            spin: true,
        },
        size: None,
        mp4: false,
        ffmpeg: None,
        skip: None,
    };
    let err = job(Some(&wav), None, "from_wav")
        .plan()
        .unwrap_err()
        .to_string();
    println!("{err}");
    assert!(!err.contains('\n'));
    assert!(
        err.contains("model.onnx") && err.contains("--features"),
        "{err}"
    );
    assert!(err.contains("another front end"), "{err}");
    assert!(!dir.path().join("from_wav").exists());
    let features = root.join("aud.npy");
    let report = job(None, Some(&features), "from_features")
        .plan()
        .unwrap()
        .render(|_| {})
        .unwrap();
    assert_eq!(report.n_frames, data.dataset.audio.n_frames);
    // Frame f is the candle student's frame of audio row f at the default track's pose.
    let info = read_model(&model).unwrap().info;
    let poses = default_track(&info, report.n_frames);
    for f in [0, 7, report.n_frames - 1] {
        let camera = nldf_core::camera::Camera {
            intrinsics: info.spec.intrinsics,
            c2w: poses[f],
        };
        let code = run.model.audio_codes(&data, &[f]).unwrap();
        let want = run
            .model
            .render_view(&camera, &data.dataset.background, &code, &data)
            .unwrap()
            .to_rgb8();
        let got = ImageRgb::load(&report.files[f]).unwrap().to_rgb8();
        let worst = want
            .iter()
            .zip(&got)
            .map(|(a, b)| (*a as i32 - *b as i32).abs())
            .max()
            .unwrap();
        assert!(worst <= 1, "frame {f}: 8-bit values differ by {worst}");
    }
}

/// AD-NeRF's near and far follow the head's mean depth along the cameras' viewing axes
/// (`mean_z`), not the cameras' distance from it: a camera beside the axis at depth 1.0 is
/// 1.118 away.
#[test]
fn ad_nerf_bounds_use_the_depth_along_the_view_axis() {
    use glam::{Mat4, Vec3};
    use nldf_core::dataset::{Frame, ad_nerf_bounds};
    let frame = |c2w: Mat4| Frame {
        img_id: 0,
        aud_id: 0,
        c2w,
        face_rect: nldf_core::image::Rect {
            x: 0,
            y: 0,
            w: 1,
            h: 1,
        },
        eye: None,
        image_path: "0.png".into(),
        parsing_path: None,
        labels_path: None,
        landmarks_path: None,
    };
    // Looking along -z from (0.5, 0, 1.0) and from (0, 0, 1.2).
    let a = frame(Mat4::from_translation(Vec3::new(0.5, 0.0, 1.0)));
    let b = frame(Mat4::from_translation(Vec3::new(0.0, 0.0, 1.2)));
    let (near, far) = ad_nerf_bounds(&[a, b]);
    assert!(
        (near - 0.9).abs() < 1e-6 && (far - 1.5).abs() < 1e-6,
        "{near} {far}"
    );
}
