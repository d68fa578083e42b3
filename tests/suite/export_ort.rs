//! Parity across every runtime: the same 10 000 random rays and audio give the same pixels
//! and segments (max abs difference <= `TOL`) in candle (the reference), tract and
//! onnxruntime through nldf-infer's backends, and Python onnxruntime; at the paper's
//! production size (88 x 256, K = 16, L = 10, attention on) within `REL_TOL` of the largest
//! output. Under CI a missing
//! onnxruntime library or Python environment fails the test instead of skipping it.

use std::path::Path;

use crate::util::{
    PYTHON_PARITY, Run, TOL, candle_render, configs, max_diff, ort_available, python, random_audio,
    random_rays, ray_background, read_npy, run_python, write_npy, write_run,
};
use nldf_core::audio::neighbourhood;
use nldf_core::rays::Rays;
use nldf_export::{WeightType, export_student_int8};
use nldf_infer::backend::{BackendKind, BackendOptions, backend_for};
use nldf_model::read_model;
use nldf_pipeline::quantize::{CalibrationFrame, activation_ranges, keep_in_f32};
use nldf_train::networks::student::StudentConfig;

/// Python onnxruntime's outputs for the rays and audio, through `.npy` files in `folder`.
fn python_render(
    python: &Path,
    model: &Path,
    folder: &Path,
    rays: &nldf_core::rays::Rays,
    audio: &[f32],
    shape: [usize; 3],
) -> Outputs {
    std::fs::create_dir_all(folder).unwrap();
    let n = rays.len() as u64;
    write_npy(&folder.join("rays_o.npy"), &[n, 3], &rays.origins);
    write_npy(&folder.join("rays_d.npy"), &[n, 3], &rays.directions);
    write_npy(
        &folder.join("background.npy"),
        &[n, 3],
        &ray_background(rays.len()),
    );
    let shape = shape.map(|d| d as u64);
    write_npy(&folder.join("audio.npy"), &shape, audio);
    run_python(
        python,
        &[
            "-c",
            PYTHON_PARITY,
            model.to_str().unwrap(),
            folder.to_str().unwrap(),
        ],
    );
    (
        read_npy(&folder.join("rgb.npy")).1,
        read_npy(&folder.join("segments.npy")).1,
    )
}

/// Pixels `[n, 3]` and segments `[n, M, 3]`, flat.
type Outputs = (Vec<f32>, Vec<f32>);

/// The outputs of `run`'s student (exported at `path`) for `rays` and `audio` in candle,
/// tract and onnxruntime (batches of `batch_size`, 2 threads) and, given its Python,
/// Python onnxruntime: `(runtime, (pixels, segments))`, candle first.
fn every_runtime(
    run: &Run,
    path: &Path,
    rays: &Rays,
    audio: &[f32],
    batch_size: usize,
    python: Option<&Path>,
) -> Vec<(String, Outputs)> {
    let model = read_model(path).unwrap();
    let mut outputs: Vec<(String, Outputs)> = Vec::new();
    outputs.push(("candle".into(), candle_render(run, rays, audio)));
    for kind in [BackendKind::Tract, BackendKind::Ort] {
        let options = BackendOptions {
            batch_size,
            threads: 2,
            spin: true,
        };
        let mut backend = backend_for(&model, kind, options).unwrap();
        let bg = ray_background(rays.len());
        let out = backend
            .run(&rays.origins, &rays.directions, &bg, audio)
            .unwrap();
        outputs.push((kind.name().into(), (out.rgb, out.segments)));
    }
    if let Some(python) = python {
        let folder = run.root.join("io");
        let shape = model.info.audio.shape();
        let out = python_render(python, path, &folder, rays, audio, shape);
        outputs.push(("python onnxruntime".into(), out));
    }
    outputs
}

#[test]
fn export_candle_tract_ort_and_python_onnxruntime_agree_on_10000_rays() {
    if !ort_available() {
        return;
    }
    let python = python();
    for (c, cfg) in configs().into_iter().enumerate() {
        let run = write_run(&cfg, 91 + c as u64);
        let path = run.export(WeightType::F32);
        let rays = random_rays(10_000, 13);
        let audio = neighbourhood(&random_audio(&cfg, 10, 14), 4, cfg.audio.att_frames);
        // 10 000 rays at batch 4096: two full batches and a partial one.
        let outputs = every_runtime(&run, &path, &rays, &audio, 4096, python.as_deref());
        for a in 0..outputs.len() {
            for b in a + 1..outputs.len() {
                let ((na, (rgb_a, seg_a)), (nb, (rgb_b, seg_b))) = (&outputs[a], &outputs[b]);
                let (d_rgb, d_seg) = (max_diff(rgb_a, rgb_b), max_diff(seg_a, seg_b));
                println!(
                    "config {c} (K {}, L {}, attention {}): {na} vs {nb}, 10000 rays: max |rgb \
                     diff| {d_rgb:.2e}, max |segment diff| {d_seg:.2e}",
                    cfg.beam.n_points, cfg.beam.n_freqs, cfg.attention
                );
                assert!(
                    d_rgb <= TOL && d_seg <= TOL,
                    "{na} vs {nb}: {d_rgb} {d_seg}"
                );
            }
        }
    }
}

/// Relative bound of the production-size parity: every output within `REL_TOL` of the
/// largest reference output's magnitude (at least 1). Measured worst about 2.0e-6.
const REL_TOL: f32 = 1e-5;

/// Parity at the paper's production size: 88 x 256 (43 residual blocks), K = 16, L = 10,
/// AudioAttNet on, weights at a trained ReLU network's magnitude. Every pair of candle,
/// tract, onnxruntime and Python onnxruntime agrees within `REL_TOL` relative to the
/// largest output.
#[test]
fn export_production_size_student_agrees_across_candle_tract_ort_and_python() {
    if !ort_available() {
        return;
    }
    let python = python();
    let cfg = StudentConfig::paper_d88();
    assert_eq!(
        (cfg.beam.n_points, cfg.beam.n_freqs, cfg.attention),
        (16, 10, true)
    );
    let run = write_run(&cfg, 88);
    run.scale_weights_like_trained(cfg.n_blocks());
    let path = run.export(WeightType::F32);
    let rays = random_rays(1500, 17);
    let audio = neighbourhood(&random_audio(&cfg, 10, 18), 4, cfg.audio.att_frames);
    let outputs = every_runtime(&run, &path, &rays, &audio, 1024, python.as_deref());
    let (rgb_ref, seg_ref) = &outputs[0].1;
    let magnitude = |v: &[f32]| v.iter().fold(0.0f32, |m, x| m.max(x.abs()));
    let scale = magnitude(rgb_ref).max(magnitude(seg_ref)).max(1.0);
    assert!(scale.is_finite(), "the reference output is not finite");
    let mut worst = 0.0f32;
    for a in 0..outputs.len() {
        for b in a + 1..outputs.len() {
            let ((na, (rgb_a, seg_a)), (nb, (rgb_b, seg_b))) = (&outputs[a], &outputs[b]);
            let d = max_diff(rgb_a, rgb_b).max(max_diff(seg_a, seg_b)) / scale;
            println!(
                "88 x 256, K 16, L 10, attention on, 1500 rays (largest output {scale:.3}): \
                 {na} vs {nb}: max relative difference {d:.2e}"
            );
            worst = worst.max(d);
            assert!(d <= REL_TOL, "{na} vs {nb}: relative difference {d}");
        }
    }
    println!("88 x 256: worst relative difference of any pair {worst:.2e}");
}

/// `frames` calibration frames of `rays` random rays each (ray seeds from `ray_seed`), the
/// audio of frame `i` the neighbourhood of window `stride * i` of a random 10-frame track
/// drawn with `audio_seed`.
fn random_calibration(
    cfg: &StudentConfig,
    frames: u64,
    rays: usize,
    ray_seed: u64,
    audio_seed: u64,
    stride: usize,
) -> Vec<CalibrationFrame> {
    let audio = random_audio(cfg, 10, audio_seed);
    (0..frames)
        .map(|i| {
            let r = random_rays(rays, ray_seed + i);
            CalibrationFrame {
                origins: r.origins,
                directions: r.directions,
                audio: neighbourhood(&audio, stride * i as usize, cfg.audio.att_frames),
            }
        })
        .collect()
}

/// int8 export at the default student's size (28 x 256, K = 16, L = 10, attention on),
/// weights at a trained ReLU network's magnitude, calibrated on other rays than those it
/// is tested on: tract, onnxruntime (batches of 1024) and Python onnxruntime (one call of
/// 1500) run the same integer products and agree with one another within
/// `INT8_RUNTIME_TOL` of the largest output, so a ray's colour does not depend on its
/// batch; each stays within the quantization's error of the f32 candle student (relative
/// RMS of the pixels at most `INT8_RMS`), while differing from it (the products really
/// are integer ones).
#[test]
fn export_int8_agrees_across_runtimes_and_stays_near_the_f32_student() {
    if !ort_available() {
        return;
    }
    let python = python();
    let cfg = StudentConfig::paper_d28();
    let run = write_run(&cfg, 28);
    run.scale_weights_like_trained(cfg.n_blocks());
    let f32_model = read_model(&run.export(WeightType::F32)).unwrap();
    let calibration = random_calibration(&cfg, 3, 1000, 40, 20, 3);
    let ranges = activation_ranges(&run.student_dir(), &f32_model.info, &calibration).unwrap();
    let path = run.root.join("model_int8.onnx");
    export_student_int8(&run.student_dir(), &path, &ranges).unwrap();
    let graph = read_model(&path).unwrap().proto.graph.unwrap();
    let count = |op: &str| {
        graph
            .node
            .iter()
            .filter(|n| n.op_type.as_deref() == Some(op))
            .count()
    };
    // The input layer's beam part and both layers of every block.
    assert_eq!(count("MatMulInteger"), 1 + 2 * cfg.n_blocks());
    assert_eq!(count("QuantizeLinear"), 1 + 2 * cfg.n_blocks());
    let f32_bytes = f32_model.bytes.len() as u64;
    let int8_bytes = std::fs::metadata(&path).unwrap().len();
    assert!(
        (int8_bytes as f64) < 0.35 * f32_bytes as f64,
        "{int8_bytes} vs {f32_bytes}"
    );
    let rays = random_rays(1500, 19);
    let audio = neighbourhood(&random_audio(&cfg, 10, 20), 4, cfg.audio.att_frames);
    let outputs = every_runtime(&run, &path, &rays, &audio, 1024, python.as_deref());
    let (rgb_ref, _) = &outputs[0].1;
    let rms =
        |v: &[f32]| (v.iter().map(|x| (*x as f64).powi(2)).sum::<f64>() / v.len() as f64).sqrt();
    let scale = rgb_ref.iter().fold(0.0f32, |m, x| m.max(x.abs())).max(1.0);
    for (name, (rgb, _)) in &outputs[1..] {
        let diff: Vec<f32> = rgb.iter().zip(rgb_ref).map(|(a, b)| a - b).collect();
        let rel = rms(&diff) / rms(rgb_ref);
        println!(
            "28 x 256 int8, 1500 rays: {name} vs the f32 candle student: relative RMS {rel:.2e}"
        );
        assert!(rel.is_finite() && rel <= INT8_RMS, "{name}: {rel}");
        assert!(rel > 1e-6, "{name}: identical to the f32 student");
    }
    for a in 1..outputs.len() {
        for b in a + 1..outputs.len() {
            let ((na, (rgb_a, seg_a)), (nb, (rgb_b, seg_b))) = (&outputs[a], &outputs[b]);
            let d = max_diff(rgb_a, rgb_b).max(max_diff(seg_a, seg_b)) / scale;
            let diff: Vec<f32> = rgb_a.iter().zip(rgb_b).map(|(a, b)| a - b).collect();
            let rel = rms(&diff) / rms(rgb_ref);
            println!(
                "28 x 256 int8: {na} vs {nb}: max relative difference {d:.2e}, relative RMS \
                 {rel:.2e}"
            );
            assert!(d <= INT8_RUNTIME_TOL, "{na} vs {nb}: {d}");
            assert!(rel <= INT8_RUNTIME_RMS, "{na} vs {nb}: {rel}");
        }
    }
}

/// Mixed precision (`nldf export --int8 --int8-f32`): a product kept in f32 loses its
/// integer product and keeps its f32 weight. Keeping every product renders the f32
/// export's pixels (tract, within `1e-5` of the largest); keeping only the last one leaves
/// one `MatMulInteger` fewer and pixels that still differ from f32. A name that is none of
/// the student's products is refused with the list of those that are.
#[test]
fn int8_products_kept_in_f32_render_as_the_f32_export() {
    let cfg = StudentConfig::tiny();
    let run = write_run(&cfg, 31);
    run.scale_weights_like_trained(cfg.n_blocks());
    let f32_path = run.export(WeightType::F32);
    let f32_model = read_model(&f32_path).unwrap();
    let calibration = random_calibration(&cfg, 2, 600, 70, 21, 1);
    let ranges = activation_ranges(&run.student_dir(), &f32_model.info, &calibration).unwrap();
    let (_, _, taps) = nldf_export::calibration_model(&run.student_dir()).unwrap();
    let products: Vec<String> = taps.iter().map(|t| t.product.clone()).collect();
    assert_eq!(products.len(), 1 + 2 * cfg.n_blocks());
    let export_keeping = |names: &[String], file: &str| {
        let mut kept = ranges.clone();
        keep_in_f32(&mut kept, &taps, names).unwrap();
        let path = run.root.join(file);
        export_student_int8(&run.student_dir(), &path, &kept).unwrap();
        path
    };
    let integer_products = |path: &Path| {
        let graph = read_model(path).unwrap().proto.graph.unwrap();
        graph
            .node
            .iter()
            .filter(|n| n.op_type.as_deref() == Some("MatMulInteger"))
            .count()
    };
    let rays = random_rays(700, 23);
    let audio = neighbourhood(&random_audio(&cfg, 10, 21), 5, cfg.audio.att_frames);
    let render = |path: &Path| {
        let model = read_model(path).unwrap();
        let options = BackendOptions {
            batch_size: 512,
            threads: 2,
            spin: false,
        };
        let mut backend = backend_for(&model, BackendKind::Tract, options).unwrap();
        let bg = ray_background(rays.len());
        let out = backend
            .run(&rays.origins, &rays.directions, &bg, &audio)
            .unwrap();
        out.rgb
    };
    let reference = render(&f32_path);
    let scale = reference
        .iter()
        .fold(0.0f32, |m, x| m.max(x.abs()))
        .max(1.0);

    let every = export_keeping(&products, "every_f32.onnx");
    assert_eq!(integer_products(&every), 0);
    let d = max_diff(&render(&every), &reference) / scale;
    assert!(d <= 1e-5, "every product kept in f32: {d}");

    let last = export_keeping(&products[products.len() - 1..], "last_f32.onnx");
    assert_eq!(integer_products(&last), products.len() - 1);
    let d = max_diff(&render(&last), &reference) / scale;
    assert!(d > 1e-6, "the other products are still in int8: {d}");

    let err = keep_in_f32(&mut ranges.clone(), &taps, &["mlp.body.99.fc1".to_string()])
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("mlp.body.99.fc1") && err.contains(&products[0]),
        "{err}"
    );
}

/// Relative RMS error allowed between the int8 model's pixels and the f32 student's.
const INT8_RMS: f64 = 0.05;

/// Largest difference allowed between two runtimes running the same int8 model, relative
/// to the largest output: a value that lands on a rounding tie in one runtime's f32
/// arithmetic and not in the other's moves one uint8 step, and the layers above carry it.
const INT8_RUNTIME_TOL: f32 = 2e-2;

/// Relative RMS difference allowed between two runtimes running the same int8 model.
/// Measured worst about 3.2e-4.
const INT8_RUNTIME_RMS: f64 = 3e-3;

/// int8 against fp32 on a trained student's frames: a tiny student trained on the recorded
/// pixels of the tiny scene, exported in f32 and in int8 (calibrated on 4 training frames),
/// both rendered by tract on every `val` frame and every `novel` frame (the head turned
/// beyond the recorded poses, so some rays leave the calibrated ranges). On each split the
/// int8 frames' head pixels are within a relative RMS of `TRAINED_INT8_RMS` of the f32
/// frames' and no channel is off by more than `TRAINED_INT8_MAX`; the frames differ.
#[test]
fn int8_stays_near_fp32_on_a_trained_students_val_and_novel_frames() {
    use nldf_core::dataset::{AudioChoice, Dataset, Split};
    use nldf_core::metrics::psnr;
    use nldf_infer::frame::FrameRenderer;
    use nldf_train::trainers::config::{StudentRunConfig, StudentTrainConfig};
    use nldf_train::trainers::data::TrainData;
    use nldf_train::trainers::student_trainer::StudentRun;
    let scene = crate::util::tiny_scene();
    let data = TrainData::load(scene).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let iters = 300;
    let cfg = StudentRunConfig {
        model: StudentConfig::tiny(),
        train: StudentTrainConfig {
            iters,
            batch_rays: 512,
            frames_per_batch: 4,
            lr: 3e-3,
            lr_decay_steps: iters,
            distill: false,
            val_every: 0,
            checkpoint_every: 0,
            ..StudentTrainConfig::default()
        },
    };
    let mut run = StudentRun::create(dir.path(), cfg, &data, None).unwrap();
    run.prepare(&data, None, &mut |_, _| {}).unwrap();
    for _ in 0..iters {
        run.train_step(&data).unwrap();
    }
    run.save().unwrap();
    let f32_path = dir.path().join("f32.onnx");
    let int8_path = dir.path().join("int8.onnx");
    nldf_export::export_student(dir.path(), &f32_path, WeightType::F32).unwrap();
    nldf_pipeline::quantize::export_int8(dir.path(), scene, 4, &int8_path).unwrap();
    let renderer = |path: &Path| {
        let model = read_model(path).unwrap();
        let att = model.info.audio.att_frames;
        let backend = backend_for(&model, BackendKind::Tract, BackendOptions::default()).unwrap();
        (FrameRenderer::new(backend, None).unwrap(), att)
    };
    let (mut fp32, att) = renderer(&f32_path);
    let (mut int8, _) = renderer(&int8_path);
    for split in [Split::Val, Split::Novel] {
        let ds = Dataset::load_held_out(scene, &AudioChoice::Auto, split).unwrap();
        let (mut p32, mut sq_diff, mut sq_base, mut worst) = (0.0, 0.0f64, 0.0f64, 0.0f32);
        for f in &ds.val {
            let truth = ds.load_image(f).unwrap();
            let audio = neighbourhood(&ds.audio, f.aud_id, att);
            let a = fp32.render(f.c2w, &audio).unwrap();
            let b = int8.render(f.c2w, &audio).unwrap();
            assert_eq!(a.head_pixels, b.head_pixels);
            p32 += psnr(&a.image, &truth).unwrap();
            // The head's pixels: the others are the background in both.
            for p in fp32.rays(f.c2w).pixels {
                for c in 3 * p..3 * p + 3 {
                    let (x, y) = (b.image.data[c], a.image.data[c]);
                    sq_diff += ((x - y) as f64).powi(2);
                    sq_base += (y as f64).powi(2);
                    worst = worst.max((x - y).abs());
                }
            }
        }
        let p32 = p32 / ds.val.len() as f64;
        let rel = (sq_diff / sq_base).sqrt();
        println!(
            "{}: {} frames, fp32 {p32:.3} dB against the ground truth; int8 against fp32: \
             relative RMS {rel:.3e} of the head pixels, worst channel {worst:.3e}",
            split.name(),
            ds.val.len()
        );
        assert!(
            p32 > 20.0,
            "{}: the student did not learn ({p32:.2} dB)",
            split.name()
        );
        assert!(
            worst > 0.0,
            "{}: the int8 frames equal the f32 ones",
            split.name()
        );
        assert!(
            rel.is_finite() && rel <= TRAINED_INT8_RMS && worst <= TRAINED_INT8_MAX,
            "{}: int8 against fp32: relative RMS {rel:.3e}, worst channel {worst:.3e}",
            split.name()
        );
    }
}

/// Relative RMS difference allowed between a trained tiny student's int8 frames and its f32
/// frames, over the head's pixels. Measured worst about 3.7e-3.
const TRAINED_INT8_RMS: f64 = 1e-2;

/// Largest difference of one colour channel allowed between the same frames. Measured
/// worst about 8.0e-3.
const TRAINED_INT8_MAX: f32 = 5e-2;
