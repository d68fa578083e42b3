//! Fuzzing harnesses of nldf's readers, shared by the test suite (a bounded, seeded run over
//! mutated valid files) and the libFuzzer targets of `fuzz/` (`scripts/fuzz.sh`). Each
//! harness feeds bytes to one reader and checks what a reader owes its user: it returns,
//! never panics; an error is one line naming the file; what it accepts is consistent.

use std::path::Path;

use rand::{Rng, RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A reader's bytes went through, or the reader broke a promise (the message says which).
pub type Verdict = Result<(), String>;

/// An error message must be one line that names `file`.
fn one_line_naming(message: &str, file: &str) -> Verdict {
    if message.contains('\n') {
        return Err(format!("error spans lines: {message:?}"));
    }
    if !message.contains(file) {
        return Err(format!("error {message:?} does not name {file}"));
    }
    Ok(())
}

/// `decode_wav`: any bytes; accepted audio is finite and non-empty.
pub fn wav(bytes: &[u8]) -> Verdict {
    match nldf_core::audio::decode_wav(bytes) {
        Ok(w) if w.samples.is_empty() => Err("accepted a WAV without samples".into()),
        Ok(w) if w.samples.iter().any(|s| !s.is_finite()) => {
            Err("accepted a non-finite sample".into())
        }
        Ok(_) => Ok(()),
        Err(problem) => one_line_naming(&problem, ""),
    }
}

/// `aud.npy`: accepted windows match their shape and are finite.
pub fn npy(bytes: &[u8]) -> Verdict {
    match nldf_core::dataset::parse_audio_npy(Path::new("aud.npy"), bytes) {
        Ok(w) => {
            if w.data.len() != w.n_frames * w.window * w.n_features || w.window != 16 {
                return Err(format!(
                    "accepted inconsistent windows {:?}",
                    (w.n_frames, w.window, w.n_features)
                ));
            }
            if w.data.iter().any(|v| !v.is_finite()) {
                return Err("accepted a non-finite feature".into());
            }
            Ok(())
        }
        Err(e) => one_line_naming(&e.to_string(), "aud.npy"),
    }
}

/// safetensors, as the exporter and the trainer read them: accepted weights are finite
/// (exporter) and shaped as their bytes say.
pub fn safetensors(bytes: &[u8]) -> Verdict {
    let path = Path::new("model.safetensors");
    match nldf_export::checkpoint::parse_weights(path, bytes) {
        Ok((weights, _)) => {
            for (name, w) in &weights {
                if w.data.len() != w.shape.iter().product::<usize>() {
                    return Err(format!(
                        "`{name}`: {} values for shape {:?}",
                        w.data.len(),
                        w.shape
                    ));
                }
                if w.data.iter().any(|v| !v.is_finite()) {
                    return Err(format!("`{name}`: accepted a non-finite weight"));
                }
            }
        }
        Err(e) => one_line_naming(&e.to_string(), "model.safetensors")?,
    }
    match nldf_train::trainers::checkpoint::parse_tensors(path, bytes) {
        Ok(_) => Ok(()),
        Err(e) => one_line_naming(&e.to_string(), "model.safetensors"),
    }
}

/// A run configuration (teacher and student): parsed strictly, then checked; an error names
/// the file, and an accepted one sizes its network without overflow.
pub fn config(bytes: &[u8]) -> Verdict {
    use nldf_train::trainers::config::{StudentRunConfig, TeacherRunConfig, parse_checked};
    let path = Path::new("config.json");
    let text = String::from_utf8_lossy(bytes);
    match parse_checked::<TeacherRunConfig>(path, &text) {
        Ok(cfg) => {
            let _ = cfg.model.macs_per_ray();
        }
        Err(e) => one_line_naming(&e.to_string(), "config.json")?,
    }
    match parse_checked::<StudentRunConfig>(path, &text) {
        Ok(cfg) => {
            let _ = cfg.model.macs_per_ray();
            Ok(())
        }
        Err(e) => one_line_naming(&e.to_string(), "config.json"),
    }
}

/// A landmarks file (`<id>.lms`): parsed, then its mouth region drawn on a small image.
pub fn landmarks(bytes: &[u8]) -> Verdict {
    let path = Path::new("0.lms");
    let text = String::from_utf8_lossy(bytes);
    match nldf_core::landmarks::Landmarks::parse(path, &text) {
        Ok(lms) => {
            if lms.points.iter().flatten().any(|v| !v.is_finite()) {
                return Err("accepted a non-finite landmark".into());
            }
            lms.mouth_mask(24, 16);
            Ok(())
        }
        Err(e) => one_line_naming(&e.to_string(), "0.lms"),
    }
}

/// An `.onnx` file as every loader checks it first (protobuf, metadata, graph, checksum).
pub fn onnx(bytes: &[u8]) -> Verdict {
    match nldf_model::load::check_model(Path::new("model.onnx"), bytes) {
        Ok((_, info)) => {
            if info.spec.check().is_err() {
                return Err("accepted metadata whose render spec fails its check".into());
            }
            Ok(())
        }
        Err(e) => one_line_naming(&e.to_string(), "model.onnx"),
    }
}

/// `transforms_train.json` of the dataset in `dir` (whose other files are valid) replaced by
/// `bytes`, then the whole dataset loaded and validated.
pub fn transforms(dir: &Path, bytes: &[u8]) -> Verdict {
    let file = dir.join("transforms_train.json");
    std::fs::write(&file, bytes).map_err(|e| format!("writing the input: {e}"))?;
    match nldf_core::dataset::Dataset::load(dir) {
        Ok(ds) => {
            if ds.train.is_empty() || !(ds.near > 0.0 && ds.far > ds.near) {
                return Err(format!(
                    "accepted a dataset with near {} far {}",
                    ds.near, ds.far
                ));
            }
            Ok(())
        }
        Err(e) => {
            let msg = e.to_string();
            if msg.contains('\n') {
                return Err(format!("error spans lines: {msg:?}"));
            }
            if !msg.contains("transforms_") && !msg.contains(&dir.display().to_string()) {
                return Err(format!("error {msg:?} names no file of the dataset"));
            }
            Ok(())
        }
    }
}

/// Byte values that break parsers more often than random ones.
const INTERESTING: [u8; 10] = [0, 1, 0x7f, 0x80, 0xff, b'-', b'9', b'e', b'"', b'{'];
/// Numbers spliced into text inputs.
const NUMBERS: [&str; 12] = [
    "-1",
    "0",
    "1e309",
    "-1e309",
    "18446744073709551616",
    "9223372036854775807",
    "1e-320",
    "4294967295",
    "NaN",
    "3.5",
    "65505",
    "-0",
];

/// A deterministic mutator over seed inputs: each case applies one to four byte-level or
/// text-level edits (bit flips, interesting bytes, inserted, deleted or duplicated runs,
/// truncation, splicing another seed, numbers swapped for extreme ones).
pub struct Mutator {
    rng: ChaCha8Rng,
    seeds: Vec<Vec<u8>>,
}

impl Mutator {
    /// A mutator over `seeds` (non-empty) seeded by `seed`.
    pub fn new(seeds: Vec<Vec<u8>>, seed: u64) -> Mutator {
        assert!(!seeds.is_empty(), "a mutator needs seed inputs");
        Mutator {
            rng: ChaCha8Rng::seed_from_u64(seed),
            seeds,
        }
    }

    /// The next input.
    pub fn next_input(&mut self) -> Vec<u8> {
        let mut data = self.seeds[self.rng.random_range(0..self.seeds.len())].clone();
        for _ in 0..self.rng.random_range(1..=4) {
            self.mutate(&mut data);
        }
        data
    }

    fn mutate(&mut self, data: &mut Vec<u8>) {
        let len = data.len();
        let at = |rng: &mut ChaCha8Rng| {
            if len == 0 {
                0
            } else {
                rng.random_range(0..len)
            }
        };
        match self.rng.random_range(0..9) {
            0 if len > 0 => {
                let i = at(&mut self.rng);
                data[i] ^= 1 << self.rng.random_range(0..8);
            }
            1 if len > 0 => {
                let i = at(&mut self.rng);
                data[i] = INTERESTING[self.rng.random_range(0..INTERESTING.len())];
            }
            2 => {
                let i = at(&mut self.rng);
                let n = self.rng.random_range(1..16);
                let mut bytes = vec![0u8; n];
                self.rng.fill_bytes(&mut bytes);
                data.splice(i..i, bytes);
            }
            3 if len > 1 => {
                let i = at(&mut self.rng);
                let n = self.rng.random_range(1..=(len - i).min(64));
                data.drain(i..i + n);
            }
            4 if len > 1 => {
                let i = at(&mut self.rng);
                let n = self.rng.random_range(1..=(len - i).min(64));
                let run = data[i..i + n].to_vec();
                data.splice(i..i, run);
            }
            5 if len > 0 => {
                let keep = self.rng.random_range(0..len);
                data.truncate(keep);
            }
            6 => {
                let other = &self.seeds[self.rng.random_range(0..self.seeds.len())];
                if !other.is_empty() {
                    let from = self.rng.random_range(0..other.len());
                    let i = at(&mut self.rng).min(data.len());
                    data.truncate(i);
                    data.extend_from_slice(&other[from..]);
                }
            }
            7 if len > 0 => {
                // Overwrite a little-endian u32 or u64 (lengths and counts in headers).
                let i = at(&mut self.rng);
                let v: u64 = match self.rng.random_range(0..4) {
                    0 => u64::MAX,
                    1 => 1 << self.rng.random_range(0..64),
                    2 => 0,
                    _ => self.rng.random(),
                };
                let bytes = v.to_le_bytes();
                let n = if self.rng.random() { 4 } else { 8 };
                for (k, b) in bytes.iter().take(n).enumerate() {
                    if let Some(slot) = data.get_mut(i + k) {
                        *slot = *b;
                    }
                }
            }
            _ => {
                // Swap a run of digits for an extreme number (text formats).
                let digits: Vec<usize> = (0..len).filter(|&i| data[i].is_ascii_digit()).collect();
                if let Some(&start) = digits.get(self.rng.random_range(0..digits.len().max(1))) {
                    let mut end = start;
                    while end < len && (data[end].is_ascii_digit() || data[end] == b'.') {
                        end += 1;
                    }
                    let n = NUMBERS[self.rng.random_range(0..NUMBERS.len())];
                    data.splice(start..end, n.bytes());
                }
            }
        }
    }
}

/// Runs `harness` on `cases` mutated inputs; returns the failures (input, message), panics
/// included (caught), at most `keep` of them.
pub fn run_cases(
    mutator: &mut Mutator,
    cases: usize,
    keep: usize,
    mut harness: impl FnMut(&[u8]) -> Verdict,
) -> Vec<(Vec<u8>, String)> {
    let mut failures = Vec::new();
    for _ in 0..cases {
        let input = mutator.next_input();
        let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| harness(&input)));
        let message = match outcome {
            Ok(Ok(())) => continue,
            Ok(Err(m)) => m,
            Err(panic) => format!(
                "panicked: {}",
                panic
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default()
            ),
        };
        if failures.len() < keep {
            failures.push((input, message));
        }
    }
    failures
}
