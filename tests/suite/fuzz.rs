//! Bounded, seeded fuzzing of every reader: valid files mutated by
//! `nldf_tests::fuzz::Mutator`, fed to the harnesses of `nldf_tests::fuzz` (the same ones
//! the libFuzzer targets of `fuzz/` run for longer, `scripts/fuzz.sh`). `NLDF_FUZZ_CASES`
//! sets the cases per reader (default below); `NLDF_FUZZ_SEED_DIR` also writes each reader's
//! seed files into `<dir>/<reader>/`, the libFuzzer corpus. Any panic or broken promise
//! fails the test and prints the inputs that caused it.

use crate::util::write_run;
use candle_core::{Device, Tensor};
use nldf_tests::fuzz::{self, Mutator, Verdict, run_cases};
use nldf_train::trainers::config::{StudentRunConfig, TeacherRunConfig};

/// Cases per reader in the test suite.
const CASES: usize = 3000;

fn cases() -> usize {
    std::env::var("NLDF_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(CASES)
}

/// Writes `seeds` into `$NLDF_FUZZ_SEED_DIR/<name>/` when that is set.
fn save_seeds(name: &str, seeds: &[Vec<u8>]) {
    if let Some(dir) = std::env::var_os("NLDF_FUZZ_SEED_DIR") {
        let dir = std::path::Path::new(&dir).join(name);
        std::fs::create_dir_all(&dir).unwrap();
        for (k, seed) in seeds.iter().enumerate() {
            std::fs::write(dir.join(format!("seed-{k}")), seed).unwrap();
        }
    }
}

#[track_caller]
fn fuzz_reader(name: &str, seeds: Vec<Vec<u8>>, seed: u64, harness: impl FnMut(&[u8]) -> Verdict) {
    save_seeds(name, &seeds);
    let n = cases();
    let mut mutator = Mutator::new(seeds, seed);
    let failures = run_cases(&mut mutator, n, 5, harness);
    println!("fuzz {name}: {n} cases, {} failures", failures.len());
    for (input, message) in &failures {
        let shown = String::from_utf8_lossy(&input[..input.len().min(300)]);
        eprintln!(
            "{name}: {message}\n  input ({} bytes): {shown:?}",
            input.len()
        );
    }
    assert!(
        failures.is_empty(),
        "{name}: {} failing inputs",
        failures.len()
    );
}

fn wav_bytes(spec: hound::WavSpec, n: usize) -> Vec<u8> {
    let mut buf = std::io::Cursor::new(Vec::new());
    let mut w = hound::WavWriter::new(&mut buf, spec).unwrap();
    for i in 0..n {
        let v = ((i as f32 * 0.1).sin() * 0.5) as f64;
        match spec.sample_format {
            hound::SampleFormat::Float => w.write_sample(v as f32).unwrap(),
            hound::SampleFormat::Int => {
                let scale = (1i64 << (spec.bits_per_sample - 1)) as f64 - 1.0;
                w.write_sample((v * scale) as i32).unwrap()
            }
        }
    }
    w.finalize().unwrap();
    buf.into_inner()
}

#[test]
fn fuzz_wav_reader() {
    let spec = |channels, bits, sample_format| hound::WavSpec {
        channels,
        sample_rate: 16_000,
        bits_per_sample: bits,
        sample_format,
    };
    let seeds = vec![
        wav_bytes(spec(1, 16, hound::SampleFormat::Int), 400),
        wav_bytes(spec(2, 24, hound::SampleFormat::Int), 100),
        wav_bytes(spec(1, 32, hound::SampleFormat::Float), 100),
        wav_bytes(spec(1, 8, hound::SampleFormat::Int), 50),
    ];
    fuzz_reader("wav", seeds, 1, fuzz::wav);
}

#[test]
fn fuzz_npy_reader() {
    let dir = tempfile::tempdir().unwrap();
    let mut seeds = Vec::new();
    for (n, f) in [(3usize, 5usize), (1, 29), (2, 1)] {
        let path = dir.path().join("a.npy");
        let w = nldf_core::audio::AudioWindows {
            n_frames: n,
            window: 16,
            n_features: f,
            data: (0..n * 16 * f).map(|i| i as f32 * 0.01).collect(),
        };
        nldf_core::dataset::save_audio_npy(&path, &w).unwrap();
        seeds.push(std::fs::read(&path).unwrap());
    }
    fuzz_reader("npy", seeds, 2, fuzz::npy);
}

#[test]
fn fuzz_safetensors_reader() {
    let dev = Device::Cpu;
    let mut seeds = Vec::new();
    for k in 1..4usize {
        let tensors: Vec<(String, Tensor)> = (0..k)
            .map(|i| {
                let t = Tensor::from_vec(
                    (0..6 * (i + 1))
                        .map(|v| v as f32 * 0.5)
                        .collect::<Vec<f32>>(),
                    (i + 1, 6),
                    &dev,
                )
                .unwrap();
                (format!("mlp.body.{i}.fc1.weight"), t)
            })
            .collect();
        let meta = crate::util::checkpoint_meta("student");
        seeds.push(safetensors::serialize(tensors, Some(meta)).unwrap());
    }
    fuzz_reader("safetensors", seeds, 3, fuzz::safetensors);
}

#[test]
fn fuzz_config_reader() {
    let seeds = vec![
        serde_json::to_vec_pretty(&TeacherRunConfig::default()).unwrap(),
        serde_json::to_vec(&StudentRunConfig::default()).unwrap(),
        br#"{"model": {"width": 64, "depth": 4}, "train": {"lr": 0.001}}"#.to_vec(),
    ];
    fuzz_reader("config", seeds, 4, fuzz::config);
}

#[test]
fn fuzz_landmarks_reader() {
    let good: String = (0..68)
        .map(|k| format!("{}.25 {}.5\n", 10 + k % 7, 20 + k / 7))
        .collect();
    let seeds = vec![
        good.clone().into_bytes(),
        good.replace(' ', ",").into_bytes(),
        b"1 2\n3 4\n".to_vec(),
    ];
    fuzz_reader("landmarks", seeds, 6, fuzz::landmarks);
}

#[test]
fn fuzz_onnx_reader() {
    let cfg = nldf_train::networks::student::StudentConfig::tiny();
    let run = write_run(&cfg, 3);
    let path = run.export(nldf_export::WeightType::F32);
    let seeds = vec![std::fs::read(path).unwrap()];
    fuzz_reader("onnx", seeds, 5, fuzz::onnx);
}

#[test]
fn fuzz_transforms_reader() {
    let dir = tempfile::tempdir().unwrap();
    let (train, _) = nldf_tests::write_tiny_dataset(dir.path());
    let seeds = vec![
        serde_json::to_vec_pretty(&train).unwrap(),
        serde_json::to_vec(&train).unwrap(),
    ];
    // Each case loads a whole dataset (files, images): fewer cases than the byte readers.
    save_seeds("transforms", &seeds);
    let root = dir.path().to_path_buf();
    let n = cases() / 6;
    let mut mutator = Mutator::new(seeds, 6);
    let failures = run_cases(&mut mutator, n, 5, |b| fuzz::transforms(&root, b));
    println!("fuzz transforms: {n} cases, {} failures", failures.len());
    for (input, message) in &failures {
        eprintln!(
            "transforms: {message}\n  input: {:?}",
            String::from_utf8_lossy(input)
        );
    }
    assert!(failures.is_empty());
}
