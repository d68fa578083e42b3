//! The stress suite: extreme numbers in, finite numbers out. Compositing with densities up
//! to 1e8 and spacings from 1e-9 to 1e10 against the f64 reference; the positional
//! encoding of coordinates up to 1e4; an exported model fed rays far outside its scene and
//! silent, clipped and very loud audio; training at ten times the learning rate.
//!
//! Tolerances: weights and colours lie in [0, 1], and the f32 paths must stay within 1e-5
//! of the f64 reference on that scale (1e-5 relative to 1); weights sum to at most 1 within
//! one part in 1e6 (f32 rounding of the sum).

use std::path::Path;
use std::sync::atomic::AtomicBool;

use crate::util::{tiny_run_config, tiny_scene, write_run};
use candle_core::{Device, Tensor};
use nldf_core::audio::{Waveform, write_wav};
use nldf_core::composite::{composite, composite_f64, segment_colors, segment_colors_f64};
use nldf_core::encoding::{MAX_COORD, MAX_ENCODING_ERROR, positional_encoding};
use nldf_export::WeightType;
use nldf_infer::backend::{BackendKind, BackendOptions, backend_for};
use nldf_infer::ort_library::find_ort_library;
use nldf_model::read_model;
use nldf_train::networks::student::StudentConfig;
use nldf_train::trainers::data::TrainData;
use nldf_train::trainers::run_loop::train_loop;
use nldf_train::trainers::teacher_trainer::TeacherRun;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A log-uniform value in `[lo, hi]`, or 0 one time in eight.
fn log_uniform(rng: &mut impl Rng, lo: f64, hi: f64) -> f64 {
    if rng.random_range(0..8) == 0 {
        return 0.0;
    }
    (lo.ln() + rng.random::<f64>() * (hi.ln() - lo.ln())).exp()
}

/// One ray's densities, spacings, `t` values (each `[64]`) and colours (`[64, 3]`).
type Ray = (Vec<f32>, Vec<f32>, Vec<f32>, Vec<f32>);

/// `n` cases of a ray of 64 samples with densities in 0..1e8 and spacings in 1e-9..1e10.
fn extreme_rays(n: usize, seed: u64) -> Vec<Ray> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            let s = 64;
            let densities: Vec<f32> = (0..s)
                .map(|_| log_uniform(&mut rng, 1e-6, 1e8) as f32)
                .collect();
            let deltas: Vec<f32> = (0..s)
                .map(|_| log_uniform(&mut rng, 1e-9, 1e10) as f32)
                .collect();
            let mut t = 0.5f32;
            let t_vals: Vec<f32> = deltas
                .iter()
                .map(|d| {
                    let here = t;
                    t = (t + d.min(1.0)).min(1e6);
                    here
                })
                .collect();
            let colors: Vec<f32> = (0..3 * s).map(|_| rng.random::<f32>()).collect();
            (densities, deltas, t_vals, colors)
        })
        .collect()
}

fn f64s(v: &[f32]) -> Vec<f64> {
    v.iter().map(|&x| x as f64).collect()
}

#[test]
fn stress_compositing_extreme_densities_and_spacings_matches_f64() {
    let (mut worst_w, mut worst_c, mut worst_seg, mut cases) = (0.0f64, 0.0f64, 0.0f64, 0);
    for (densities, deltas, t_vals, colors) in extreme_rays(400, 1) {
        let rgb64: Vec<[f64; 3]> = colors
            .chunks_exact(3)
            .map(|c| [c[0] as f64, c[1] as f64, c[2] as f64])
            .collect();
        let want = composite_f64(&f64s(&densities), &f64s(&deltas), &f64s(&t_vals), &rgb64);
        let got = composite(&densities, &deltas, &t_vals, &colors);
        assert!(got.weights.iter().all(|w| w.is_finite() && *w >= 0.0));
        assert!(got.color.iter().all(|c| c.is_finite()) && got.depth.is_finite());
        let sum: f32 = got.weights.iter().sum();
        assert!(sum <= 1.0 + 1e-6, "weights sum to {sum}");
        for (a, b) in got.weights.iter().zip(&want.weights) {
            worst_w = worst_w.max((*a as f64 - b).abs());
        }
        for c in 0..3 {
            worst_c = worst_c.max((got.color[c] as f64 - want.color[c]).abs());
        }
        let span = (t_vals[0], t_vals[63]);
        let seg = segment_colors(&got.weights, &colors, &t_vals, span, 4);
        let seg64 = segment_colors_f64(
            &want.weights,
            &rgb64,
            &f64s(&t_vals),
            (span.0 as f64, span.1 as f64),
            4,
        );
        for i in 0..4 {
            for c in 0..3 {
                worst_seg = worst_seg.max((seg[3 * i + c] as f64 - seg64[i][c]).abs());
            }
        }
        cases += 1;
    }
    println!(
        "core f32 compositing, {cases} rays of 64 samples: worst weight error {worst_w:.2e}, \
         colour {worst_c:.2e}, segment {worst_seg:.2e}"
    );
    // Measured worst about 7e-8 (weights, colours and segments).
    assert!(worst_w <= 5e-7 && worst_c <= 5e-7 && worst_seg <= 5e-7);
}

#[test]
fn stress_candle_compositing_extreme_densities_and_spacings_matches_f64() {
    let rays = extreme_rays(256, 2);
    let (n, s) = (rays.len(), 64);
    let flat = |k: usize| -> Vec<f32> {
        rays.iter()
            .flat_map(|r| match k {
                0 => r.0.clone(),
                1 => r.1.clone(),
                _ => r.3.clone(),
            })
            .collect()
    };
    let t = |v: Vec<f32>, shape: &[usize]| Tensor::from_vec(v, shape, &Device::Cpu).unwrap();
    let bg = vec![0.25f32; 3 * n];
    let out = nldf_train::networks::render::composite(
        &t(flat(0), &[n, s]),
        &t(flat(1), &[n, s]),
        &t(flat(2), &[n, s, 3]),
        &t(bg.clone(), &[n, 3]),
    )
    .unwrap();
    let color: Vec<Vec<f32>> = out.color.to_vec2().unwrap();
    let weights: Vec<Vec<f32>> = out.weights.to_vec2().unwrap();
    let mut worst = 0.0f64;
    for (r, (densities, deltas, t_vals, colors)) in rays.iter().enumerate() {
        let rgb64: Vec<[f64; 3]> = colors
            .chunks_exact(3)
            .map(|c| [c[0] as f64, c[1] as f64, c[2] as f64])
            .collect();
        let want = composite_f64(&f64s(densities), &f64s(deltas), &f64s(t_vals), &rgb64);
        assert!(weights[r].iter().sum::<f32>() <= 1.0 + 1e-6);
        for (w, want_w) in weights[r].iter().zip(&want.weights) {
            worst = worst.max((*w as f64 - want_w).abs());
        }
        for (c, want_c) in color[r].iter().zip(want.color) {
            let with_bg = want_c + (1.0 - want.opacity) * 0.25;
            assert!(c.is_finite());
            worst = worst.max((*c as f64 - with_bg).abs());
        }
    }
    println!("candle compositing, {n} extreme rays: worst error {worst:.2e}");
    // Measured worst about 9e-8.
    assert!(worst <= 5e-7);
}

#[test]
fn stress_encoding_of_coordinates_up_to_1e4_is_finite_and_exact_to_f32() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut values: Vec<f32> = (0..4000)
        .map(|i| {
            let scale = [2.0f32, 100.0, 1e4][i % 3];
            rng.random_range(-scale..scale)
        })
        .collect();
    values.extend([
        0.0, -0.0, MAX_COORD, -MAX_COORD, 1e-30, 9999.999, -1234.5678,
    ]);
    let enc = positional_encoding(&values, 10);
    assert!(enc.iter().all(|v| v.is_finite()));
    let n = values.len();
    let mut worst = 0.0f64;
    for l in 0..10 {
        for (i, &x) in values.iter().enumerate() {
            let arg = (1u64 << l) as f64 * x as f64;
            let (s, c) = (
                enc[n + 2 * n * l + i] as f64,
                enc[2 * n + 2 * n * l + i] as f64,
            );
            worst = worst.max((s - arg.sin()).abs()).max((c - arg.cos()).abs());
        }
    }
    println!("encoding of |x| <= 1e4, L = 10: worst error against f64 {worst:.2e}");
    assert!(worst <= MAX_ENCODING_ERROR, "{worst}");
}

/// Writes a float WAV of `samples` at 16 kHz (float WAVs may exceed full scale).
fn write_float_wav(path: &Path, samples: &[f32]) {
    let spec = hound::WavSpec {
        channels: 1,
        sample_rate: 16_000,
        bits_per_sample: 32,
        sample_format: hound::SampleFormat::Float,
    };
    let mut w = hound::WavWriter::create(path, spec).unwrap();
    for &s in samples {
        w.write_sample(s).unwrap();
    }
    w.finalize().unwrap();
}

#[test]
fn stress_exported_model_gives_finite_output_for_far_rays_and_extreme_audio() {
    let cfg = StudentConfig::tiny();
    let run = write_run(&cfg, 44);
    let path = run.export(WeightType::F32);
    let model = read_model(&path).unwrap();
    let info = &model.info;
    // Rays far outside the scene, huge and tiny directions, grazing and backwards rays.
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let (mut origins, mut directions) = (Vec::new(), Vec::new());
    for k in 0..600 {
        let scale = [1e6f32, 1e3, 1.0][k % 3];
        let dscale = [1e3f32, 1e-9, 1.0, 1e6][k % 4];
        for _ in 0..3 {
            origins.push(rng.random_range(-scale..scale));
            directions.push(rng.random_range(-dscale..dscale));
        }
    }
    // Audio: silence, a clipped full-scale square wave, and a float WAV at 1e4 x full scale.
    let dir = run.root.join("audio");
    std::fs::create_dir_all(&dir).unwrap();
    let n = 8000;
    let silent = Waveform {
        sample_rate: 16_000,
        samples: vec![0.0; n],
    };
    write_wav(&dir.join("silent.wav"), &silent).unwrap();
    let square: Vec<f32> = (0..n)
        .map(|i| if (i / 20) % 2 == 0 { 1.5 } else { -1.5 })
        .collect();
    write_wav(
        &dir.join("clipped.wav"),
        &Waveform {
            sample_rate: 16_000,
            samples: square.clone(),
        },
    )
    .unwrap();
    write_float_wav(
        &dir.join("loud.wav"),
        &square.iter().map(|s| s * 1e4).collect::<Vec<_>>(),
    );
    let mut kinds = vec![BackendKind::Tract];
    if find_ort_library().is_ok() || nldf_tests::in_ci() {
        kinds.push(BackendKind::Ort);
    }
    let mut checked = 0;
    for wav in ["silent.wav", "clipped.wav", "loud.wav"] {
        let windows = nldf_infer::audio::windows_from_wav(info, &path, &dir.join(wav)).unwrap();
        assert!(windows.data.iter().all(|v| v.is_finite()), "{wav} features");
        for f in [0, windows.n_frames - 1] {
            let audio = nldf_core::audio::neighbourhood(&windows, f, info.audio.att_frames);
            for &kind in &kinds {
                let options = BackendOptions {
                    batch_size: 512,
                    threads: 1,
                    spin: true,
                };
                let mut b = backend_for(&model, kind, options).unwrap();
                let bg = vec![0.5f32; origins.len()];
                let out = b.run(&origins, &directions, &bg, &audio).unwrap();
                assert!(
                    out.rgb
                        .iter()
                        .chain(&out.segments)
                        .chain(&out.opacity)
                        .all(|v| v.is_finite()),
                    "{kind} with {wav}: non-finite output"
                );
                checked += 1;
            }
        }
    }
    println!("exported model, 600 far rays: finite in {checked} runs ({kinds:?})");
}

/// Ten times the default learning rate, for the MLP and the grid teacher: the run either
/// finishes or stops with a one-line error, and every checkpoint it leaves holds finite
/// weights only.
#[test]
fn stress_training_at_ten_times_the_learning_rate_never_checkpoints_a_nan() {
    for cfg in [tiny_run_config(60), crate::util::tiny_grid_run_config(60)] {
        ten_times_the_learning_rate(cfg);
    }
}

fn ten_times_the_learning_rate(mut cfg: nldf_train::trainers::config::TeacherRunConfig) {
    let data = TrainData::load(tiny_scene()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    cfg.train.lr *= 10.0;
    cfg.train.checkpoint_every = 10;
    let mut run = TeacherRun::create(dir.path(), cfg, &data).unwrap();
    let result = train_loop(&mut run, &data, &AtomicBool::new(false), &mut |_| {});
    match &result {
        Ok(_) => println!("teacher at 10x lr: finished {} steps", run.model.step),
        Err(e) => {
            let msg = e.to_string();
            println!("teacher at 10x lr: {msg}");
            assert!(msg.contains("diverged") && !msg.contains('\n'), "{msg}");
        }
    }
    let (tensors, _) =
        nldf_train::trainers::checkpoint::load_tensors(&dir.path().join("model.safetensors"))
            .unwrap();
    assert_eq!(
        nldf_train::trainers::checkpoint::first_non_finite(&tensors).unwrap(),
        None
    );
}
