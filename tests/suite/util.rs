//! Fixtures shared by the suite's modules: seeded student runs as the trainer leaves them
//! and their candle reference renders, random rays and audio, the tiny synthetic scene and
//! teacher settings, the Python and onnxruntime environments, `.npy` and WAV files.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use candle_core::{DType, Device, Tensor};
use glam::{Mat4, Vec3};
use nldf_core::audio::{AudioWindows, FeatureConfig, FeatureSource, Waveform, write_wav};
use nldf_core::beam::BeamAnchor;
use nldf_core::bounds::Bounds;
use nldf_core::camera::{Camera, Intrinsics, look_at};
use nldf_core::image::ImageRgb;
use nldf_core::rays::{Rays, head_rays};
use nldf_core::render_spec::{BACKGROUND_FILE, RENDER_SPEC_FILE, RenderSpec};
use nldf_core::run_files::{CHECKPOINT_VERSION, CHECKPOINT_VERSION_KEY};
use nldf_core::synth::{SynthConfig, generate};
use nldf_export::{WeightType, export_student};
use nldf_infer::ort_library::find_ort_library;
use nldf_model::onnx::{ModelProto, StringStringEntryProto};
use nldf_train::networks::nn::{init_seeded, new_varmap, sorted_vars};
use nldf_train::networks::student::{Student, StudentConfig, student};
use nldf_train::trainers::checkpoint::{save_tensors, weights};
use nldf_train::trainers::config::{TeacherConfig, TeacherRunConfig, TeacherTrainConfig};
use prost::Message;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Parity tolerance across runtimes for the tiny students: max abs difference on every
/// output value. Measured worst about 8.3e-7.
pub(crate) const TOL: f32 = 5e-6;

/// A student run folder and the candle student whose weights it holds.
pub(crate) struct Run {
    _dir: tempfile::TempDir,
    pub(crate) root: PathBuf,
    pub(crate) student: Student,
    varmap: candle_nn::VarMap,
    pub(crate) spec: RenderSpec,
}

impl Run {
    pub(crate) fn student_dir(&self) -> PathBuf {
        self.root.join("student")
    }

    pub(crate) fn export(&self, weights: WeightType) -> PathBuf {
        let out = self.root.join(match weights {
            WeightType::F32 => "model.onnx",
            WeightType::F16 => "model_fp16.onnx",
            WeightType::Int8 => "model_int8.onnx",
        });
        export_student(&self.student_dir(), &out, weights).unwrap();
        out
    }

    /// Scales the weights (not the biases) to a trained deep ReLU network's magnitude and
    /// writes them back into the run folder: He's standard deviation `sqrt(2 / fan_in)` for
    /// the input and output layers and each block's first layer, and He's divided by the
    /// square root of the number of blocks for each block's second layer (the residual
    /// branch), so that the residual stream stays finite through every block.
    pub(crate) fn scale_weights_like_trained(&self, n_blocks: usize) {
        // The seeded initialisation is uniform in +-1/sqrt(fan_in): std 1/sqrt(3 fan_in).
        let he = 6f64.sqrt();
        for (name, var) in sorted_vars(&self.varmap).unwrap() {
            if !name.ends_with("weight") || name.starts_with("audio.") {
                continue;
            }
            let factor = if name.contains(".fc2.") {
                he / (n_blocks as f64).sqrt()
            } else {
                he
            };
            var.set(&(var.as_tensor() * factor).unwrap()).unwrap();
        }
        save_student(&self.student_dir(), &self.varmap);
    }

    /// Multiplies the audio encoder's weights by `gain` and saves the checkpoint: a larger
    /// gain makes the frame follow the audio over more of the head.
    pub(crate) fn scale_audio_weights(&self, gain: f64) {
        for (name, var) in sorted_vars(&self.varmap).unwrap() {
            if name.starts_with("audio.") && name.ends_with("weight") {
                var.set(&(var.as_tensor() * gain).unwrap()).unwrap();
            }
        }
        save_student(&self.student_dir(), &self.varmap);
    }

    /// Rounds every weight of the candle student to f16 and back (the fp16 model's
    /// values).
    pub(crate) fn round_weights_to_f16(&self) {
        for (_, var) in sorted_vars(&self.varmap).unwrap() {
            let rounded = var
                .as_tensor()
                .to_dtype(DType::F16)
                .unwrap()
                .to_dtype(DType::F32)
                .unwrap();
            var.set(&rounded).unwrap();
        }
    }
}

/// Writes the weights of `varmap` as the student checkpoint of `student_dir`.
fn save_student(student_dir: &Path, varmap: &candle_nn::VarMap) {
    save_tensors(
        &student_dir.join("model.safetensors"),
        &weights(varmap).unwrap(),
        checkpoint_meta("student"),
    )
    .unwrap();
}

/// The camera of `spec_for` at `width` x `height` pixels with the same field of view.
pub(crate) fn camera_at(width: u32, height: u32) -> Intrinsics {
    let scale = width as f32 / 24.0;
    Intrinsics {
        focal: 30.0 * scale,
        cx: width as f32 / 2.0,
        cy: height as f32 / 2.0,
        width,
        height,
    }
}

/// A 24 x 18 camera looking at a head in [-0.5, 0.5]^3 from about 2.2 away.
pub(crate) fn spec_for(cfg: &StudentConfig) -> RenderSpec {
    let c2w = look_at(Vec3::new(0.3, 0.2, 2.2), Vec3::ZERO, Vec3::Y);
    RenderSpec {
        intrinsics: Intrinsics {
            focal: 30.0,
            cx: 12.0,
            cy: 9.0,
            width: 24,
            height: 18,
        },
        near: 1.4,
        far: 3.0,
        fps: 25.0,
        bounds: Bounds {
            lo: Vec3::splat(-0.5),
            hi: Vec3::splat(0.5),
        },
        background: BACKGROUND_FILE.to_string(),
        features: FeatureSource::Nldf(FeatureConfig {
            n_mels: cfg.audio.n_features,
            window: cfg.audio.window,
            ..FeatureConfig::default()
        }),
        att_frames: cfg.audio.att_frames,
        default_pose: c2w.transpose().to_cols_array_2d(),
    }
}

/// Writes `RUN/student/` for a seeded, untrained student of shape `cfg`, as the trainer
/// leaves it: weights with step metadata, config.json, render.json and the background.
pub(crate) fn write_run(cfg: &StudentConfig, seed: u64) -> Run {
    write_run_with(cfg, seed, spec_for(cfg))
}

/// The safetensors metadata of a checkpoint of `kind` (`student`, `upsampler`) at step 7,
/// as the trainer writes it: with this build's checkpoint version.
pub(crate) fn checkpoint_meta(kind: &str) -> HashMap<String, String> {
    HashMap::from([
        ("step".to_string(), "7".to_string()),
        ("kind".to_string(), kind.to_string()),
        (
            CHECKPOINT_VERSION_KEY.to_string(),
            CHECKPOINT_VERSION.to_string(),
        ),
    ])
}

/// [`write_run`] with the render spec `spec` (another camera or image size). A `cfg`
/// without a beam anchor is anchored at the head from the spec's camera, as the trainer
/// anchors every student (the student in the returned run holds it).
pub(crate) fn write_run_with(cfg: &StudentConfig, seed: u64, spec: RenderSpec) -> Run {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("run");
    let student_dir = root.join("student");
    std::fs::create_dir_all(&student_dir).unwrap();
    let mut cfg = cfg.clone();
    if cfg.beam.anchor.is_none() {
        let c2w = Mat4::from_cols_array_2d(&spec.default_pose).transpose();
        cfg.beam.anchor = BeamAnchor::of_cameras(spec.bounds.centre(), &[c2w]);
    }
    let (varmap, vb) = new_varmap();
    let model = student(&cfg, vb).unwrap();
    init_seeded(&varmap, seed).unwrap();
    save_student(&student_dir, &varmap);
    let config = serde_json::json!({ "model": cfg, "seed": seed, "lr": 5e-4 });
    std::fs::write(student_dir.join("config.json"), config.to_string()).unwrap();
    spec.save(&student_dir.join(RENDER_SPEC_FILE)).unwrap();
    let k = spec.intrinsics;
    nldf_tests::pattern_image(k.width, k.height, 5)
        .save_png(&student_dir.join(BACKGROUND_FILE))
        .unwrap();
    Run {
        _dir: dir,
        root,
        student: model,
        varmap,
        spec,
    }
}

/// `n` rays from points around the camera distance towards the head, some missing it.
pub(crate) fn random_rays(n: usize, seed: u64) -> Rays {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut rays = Rays::with_capacity(n);
    for _ in 0..n {
        let o = Vec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(1.5..2.5),
        );
        let target = Vec3::new(
            rng.random_range(-0.8..0.8),
            rng.random_range(-0.8..0.8),
            rng.random_range(-0.8..0.8),
        );
        // Un-normalised, as camera rays are: unit depth along the view axis, give or take.
        let d = (target - o).normalize() * rng.random_range(0.9..1.3);
        rays.push(o, d);
    }
    rays
}

/// A random audio track of `n_frames` windows for `cfg`.
pub(crate) fn random_audio(cfg: &StudentConfig, n_frames: usize, seed: u64) -> AudioWindows {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (window, n_features) = (cfg.audio.window, cfg.audio.n_features);
    AudioWindows {
        n_frames,
        window,
        n_features,
        data: (0..n_frames * window * n_features)
            .map(|_| rng.random_range(-1.0..1.0))
            .collect(),
    }
}

/// A background colour behind each of `n` rays, `[n, 3]` flat in [0, 1], varied from ray
/// to ray: what the parity tests composite a model with opacity over.
pub(crate) fn ray_background(n: usize) -> Vec<f32> {
    (0..3 * n)
        .map(|k| ((k as f32 * 0.618_034).fract() * 0.9 + 0.05).min(1.0))
        .collect()
}

/// The candle reference: pixels `[n, 3]` and segments `[n, m, 3]`, flat; a student with
/// opacity composites over [`ray_background`].
pub(crate) fn candle_render(run: &Run, rays: &Rays, audio: &[f32]) -> (Vec<f32>, Vec<f32>) {
    let bg = ray_background(rays.len());
    candle_render_over(run, rays, audio, &bg)
}

/// [`candle_render`] over the background `bg` (`[n, 3]` flat).
pub(crate) fn candle_render_over(
    run: &Run,
    rays: &Rays,
    audio: &[f32],
    bg: &[f32],
) -> (Vec<f32>, Vec<f32>) {
    let a = &run.student.cfg.audio;
    let nb = Tensor::from_vec(
        audio.to_vec(),
        (1, a.att_frames, a.window, a.n_features),
        &Device::Cpu,
    )
    .unwrap();
    let out = run
        .student
        .render_rays(rays, &nb, run.spec.near, run.spec.far)
        .unwrap();
    let bg = Tensor::from_vec(bg.to_vec(), (rays.len(), 3), &Device::Cpu).unwrap();
    let pixels = out.pixels(&bg).unwrap();
    let flat = |t: Tensor| t.flatten_all().unwrap().to_vec1::<f32>().unwrap();
    (flat(pixels), flat(out.segments))
}

pub(crate) fn max_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len(), "output lengths");
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(
            0.0,
            |m, d| if d.is_nan() { f32::INFINITY } else { m.max(d) },
        )
}

/// Shapes exercised: the tiny preset (attention on) and the paper's beam (K = 16, L = 10)
/// on a narrow network without attention, other audio sizes.
pub(crate) fn configs() -> Vec<StudentConfig> {
    let mut paper_beam = StudentConfig::tiny();
    paper_beam.beam = Default::default();
    paper_beam.depth = 4;
    paper_beam.width = 16;
    paper_beam.attention = false;
    paper_beam.audio.n_features = 5;
    paper_beam.audio.features = FeatureSource::Nldf(FeatureConfig {
        n_mels: 5,
        ..FeatureConfig::default()
    });
    paper_beam.audio.att_frames = 4;
    paper_beam.segments = 3;
    // The tiny student's anchor has its centre off the origin, so that the anchor's
    // arithmetic is exercised in full; the other is anchored from the camera when its run
    // is written, as the trainer anchors it.
    let mut anchored = StudentConfig::tiny();
    anchored.beam.anchor = Some(BeamAnchor {
        centre: [0.05, -0.03, 0.02],
        distance: 2.2,
    });
    vec![anchored, paper_beam]
}

/// A valid ONNX model (an Identity) with the given metadata.
pub(crate) fn foreign_model(metadata: Vec<StringStringEntryProto>) -> Vec<u8> {
    use nldf_export::graph::{Dim, GraphBuilder};
    use nldf_model::onnx::{DataType, OperatorSetIdProto};
    let mut g = GraphBuilder::new(WeightType::F32);
    g.input("x", DataType::Float, &[Dim::Fixed(2)]);
    g.node("Identity", "y", &["x"], vec![]);
    g.output("y", DataType::Float, &[Dim::Fixed(2)]);
    ModelProto {
        ir_version: Some(8),
        opset_import: vec![OperatorSetIdProto {
            domain: Some(String::new()),
            version: Some(17),
        }],
        graph: Some(g.finish("other", "")),
        metadata_props: metadata,
        ..Default::default()
    }
    .encode_to_vec()
}

/// The project's Python (`.venv`, made by `scripts/python_env.sh`) with onnx, onnxruntime
/// and numpy, or `None` (after saying so) when it is missing outside CI. Under CI a missing
/// environment fails the test.
pub(crate) fn python() -> Option<PathBuf> {
    let venv = Path::new(env!("CARGO_MANIFEST_DIR")).join("../.venv/bin/python");
    let ok = Command::new(&venv)
        .args(["-c", "import onnx, onnxruntime, numpy"])
        .status()
        .is_ok_and(|s| s.success());
    if ok {
        return Some(venv);
    }
    let msg = format!(
        "{} with onnx, onnxruntime and numpy is missing: run scripts/python_env.sh",
        venv.display()
    );
    nldf_tests::tool_missing(msg)
}

/// The ffmpeg binary of the `.venv`'s imageio-ffmpeg wheel (scripts/python_env.sh); `None`
/// (a skip) only outside CI.
pub(crate) fn venv_ffmpeg() -> Option<PathBuf> {
    let py = python()?;
    let out = Command::new(&py)
        .args([
            "-c",
            "import imageio_ffmpeg; print(imageio_ffmpeg.get_ffmpeg_exe())",
        ])
        .output()
        .unwrap();
    if out.status.success() {
        return Some(PathBuf::from(String::from_utf8_lossy(&out.stdout).trim()));
    }
    let msg = "the .venv lacks imageio-ffmpeg: run scripts/python_env.sh";
    nldf_tests::tool_missing(msg)
}

pub(crate) fn run_python(python: &Path, args: &[&str]) -> String {
    let out = Command::new(python).args(args).output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(
        out.status.success(),
        "python {args:?} failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    stdout
}

pub(crate) fn write_npy(path: &Path, shape: &[u64], data: &[f32]) {
    use npyz::WriterBuilder;
    let mut buf = Vec::new();
    let mut w = npyz::WriteOptions::new()
        .default_dtype()
        .shape(shape)
        .writer(&mut buf)
        .begin_nd()
        .unwrap();
    w.extend(data.iter().copied()).unwrap();
    w.finish().unwrap();
    std::fs::write(path, buf).unwrap();
}

pub(crate) fn read_npy(path: &Path) -> (Vec<u64>, Vec<f32>) {
    let bytes = std::fs::read(path).unwrap();
    let npy = npyz::NpyFile::new(&bytes[..]).unwrap();
    let shape = npy.shape().to_vec();
    (shape, npy.into_vec::<f32>().unwrap())
}

pub(crate) const PYTHON_PARITY: &str = r#"
import json, sys
import numpy as np, onnx, onnxruntime as ort
path, folder = sys.argv[1], sys.argv[2]
model = onnx.load(path)
onnx.checker.check_model(model, full_check=True)
session = ort.InferenceSession(path, providers=["CPUExecutionProvider"])
names = [i.name for i in session.get_inputs()]
feeds = {name: np.load(f"{folder}/{name}.npy") for name in names}
rgb, segments = session.run(["rgb", "segments"], feeds)
np.save(f"{folder}/rgb.npy", rgb)
np.save(f"{folder}/segments.npy", segments)
dims = [d.dim_param or d.dim_value for d in model.graph.input[0].type.tensor_type.shape.dim]
print(json.dumps({"ir_version": model.ir_version, "opset": model.opset_import[0].version,
                  "rays_o": dims, "onnxruntime": ort.__version__}))
"#;

/// The candle reference frame: the rays of the frame seen from `c2w` with `intrinsics` that
/// meet the head's bounds ([`head_rays`]) get the candle student's colour, the other pixels
/// the background.
pub(crate) fn candle_frame(
    run: &Run,
    intrinsics: Intrinsics,
    c2w: Mat4,
    audio: &[f32],
    background: &ImageRgb,
) -> ImageRgb {
    let spec = &run.spec;
    let camera = Camera { intrinsics, c2w };
    let head = head_rays(&camera, &spec.head_range());
    let mut frame = background.clone();
    if !head.pixels.is_empty() {
        let bg = background.gather(&head.pixels);
        let (rgb, _) = candle_render_over(run, &head.rays, audio, &bg);
        frame.paint(&head.pixels, &rgb);
    }
    frame
}

/// Whether the onnxruntime library can be found; outside CI a missing one skips (after
/// saying so), under CI it fails.
/// The runtimes a test holds against each other: tract, and onnxruntime where its library
/// is here (under CI a missing one fails, see [`ort_available`]).
pub(crate) fn runtimes() -> Vec<nldf_infer::BackendKind> {
    let mut kinds = vec![nldf_infer::BackendKind::Tract];
    if ort_available() {
        kinds.push(nldf_infer::BackendKind::Ort);
    }
    kinds
}

pub(crate) fn ort_available() -> bool {
    match find_ort_library() {
        Ok(_) => true,
        Err(e) => nldf_tests::tool_missing::<()>(e).is_some(),
    }
}

/// A 16 kHz tone with a wobbling pitch, `seconds` long.
pub(crate) fn write_test_wav(path: &Path, seconds: f32) {
    let n = (16_000.0 * seconds) as usize;
    let samples = (0..n)
        .map(|i| {
            let t = i as f32 / 16_000.0;
            0.4 * (2.0 * std::f32::consts::PI * (220.0 + 80.0 * (3.0 * t).sin()) * t).sin()
        })
        .collect();
    write_wav(
        path,
        &Waveform {
            sample_rate: 16_000,
            samples,
        },
    )
    .unwrap();
}

/// A 32 x 32, 2 s synthetic scene shared by the training tests.
pub(crate) fn tiny_scene() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = tempfile::Builder::new()
            .prefix("teacher-scene")
            .tempdir_in(env!("CARGO_TARGET_TMPDIR"))
            .unwrap()
            .keep();
        let out = dir.join("scene");
        let cfg = SynthConfig {
            seconds: 2.0,
            size: 32,
            supersample: 1,
            ..SynthConfig::default()
        };
        generate(&cfg, None, &out, false, &|| {}).unwrap();
        out
    })
}

pub(crate) fn tiny_run_config(iters: usize) -> TeacherRunConfig {
    TeacherRunConfig {
        model: TeacherConfig::tiny(),
        train: TeacherTrainConfig {
            iters,
            batch_rays: 256,
            frames_per_batch: 2,
            lr: 5e-3,
            att_start: 4,
            val_every: 0,
            val_frames: 2,
            checkpoint_every: 0,
            ..TeacherTrainConfig::default()
        },
    }
}

/// [`tiny_run_config`] with a small grid teacher: 8 levels of 2 features (4 to 64 cells,
/// tables of 2^12) under 2 x 32.
pub(crate) fn tiny_grid_run_config(iters: usize) -> TeacherRunConfig {
    let mut cfg = tiny_run_config(iters);
    cfg.model.depth = 2;
    cfg.model.skips = vec![];
    cfg.model.grid = Some(nldf_train::networks::hash_grid::GridConfig {
        levels: 8,
        log2_table: 12,
        base_resolution: 4,
        max_resolution: 64,
        ..Default::default()
    });
    cfg
}

/// A teacher of `cfg` on the tiny scene learns in 200 steps ([`assert_learned`]).
pub(crate) fn assert_teacher_learns(what: &str, cfg: TeacherRunConfig) {
    let data = nldf_train::trainers::data::TrainData::load(tiny_scene()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut run =
        nldf_train::trainers::teacher_trainer::TeacherRun::create(dir.path(), cfg, &data).unwrap();
    let before = run.model.validation_scores(&data, 2).unwrap();
    let mut losses = Vec::new();
    for _ in 0..200 {
        losses.push(run.train_step(&data).unwrap().0);
    }
    let after = run.model.validation_scores(&data, 2).unwrap();
    assert_learned(what, &losses, 0.6, before.psnr, after.psnr);
}

/// A teacher of `cfg` (20 steps) saved after 6 steps and resumed takes the same next two
/// steps bit for bit; one opened without its optimizer's moments does not.
pub(crate) fn assert_teacher_resumes_bit_for_bit(cfg: TeacherRunConfig) {
    use nldf_train::trainers::teacher_trainer::{TeacherModel, TeacherRun};
    let data = nldf_train::trainers::data::TrainData::load(tiny_scene()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut run = TeacherRun::create(dir.path(), cfg, &data).unwrap();
    for _ in 0..6 {
        run.train_step(&data).unwrap();
    }
    run.save().unwrap();
    let (a1, _) = run.train_step(&data).unwrap();
    let (a2, _) = run.train_step(&data).unwrap();
    let mut resumed = TeacherRun::open(dir.path()).unwrap();
    assert_eq!(resumed.model.step, 6);
    let (b1, _) = resumed.train_step(&data).unwrap();
    let (b2, _) = resumed.train_step(&data).unwrap();
    assert_eq!(a1.to_bits(), b1.to_bits(), "{a1} vs {b1}");
    assert_eq!(a2.to_bits(), b2.to_bits(), "{a2} vs {b2}");
    // Without the optimizer state the second step would differ: the check can fail.
    let mut cold = TeacherRun::from_model(TeacherModel::open(dir.path()).unwrap()).unwrap();
    cold.train_step(&data).unwrap();
    let (c2, _) = cold.train_step(&data).unwrap();
    assert_ne!(a2.to_bits(), c2.to_bits());
}

/// A training run learned: every loss finite, the mean of the last 10 losses below `ratio`
/// times the mean of the first 10, and the validation PSNR up by more than 2 dB.
pub(crate) fn assert_learned(what: &str, losses: &[f64], ratio: f64, before: f64, after: f64) {
    assert!(
        losses.iter().all(|l| l.is_finite()),
        "{what}: a loss is not finite"
    );
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let (first, last) = (mean(&losses[..10]), mean(&losses[losses.len() - 10..]));
    eprintln!("{what} loss {first:.4e} -> {last:.4e}, val PSNR {before:.2} -> {after:.2} dB");
    assert!(last < ratio * first, "{what}: loss {first} -> {last}");
    assert!(after > before + 2.0, "{what}: PSNR {before} -> {after}");
}

/// Every file under `root`, by its path relative to `root`, with its bytes.
pub(crate) fn files_under(root: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                out.insert(
                    path.strip_prefix(root).unwrap().to_path_buf(),
                    std::fs::read(&path).unwrap(),
                );
            }
        }
    }
    out
}

/// The name and shape of every tensor in the safetensors file at `path`.
pub(crate) fn tensor_shapes(path: &Path) -> std::collections::BTreeMap<String, Vec<usize>> {
    candle_core::safetensors::load(path, &candle_core::Device::Cpu)
        .unwrap()
        .iter()
        .map(|(name, t)| (name.clone(), t.dims().to_vec()))
        .collect()
}
