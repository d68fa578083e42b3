//! Shared helpers for the workspace test suite: small hand-made datasets, assertions and the
//! readers' fuzzing harnesses ([`fuzz`]).

pub mod fuzz;

use std::path::Path;

use glam::{Mat4, Vec3};
use nldf_core::audio::AudioWindows;
use nldf_core::camera::look_at;
use nldf_core::dataset::{FrameEntry, TransformsFile, save_audio_npy};
use nldf_core::image::{ImageRgb, Rect};

/// Rows of a matrix, as transforms files store them.
pub fn rows(m: &Mat4) -> [[f32; 4]; 4] {
    m.transpose().to_cols_array_2d()
}

/// A deterministic image whose pixels depend on `seed`.
pub fn pattern_image(width: u32, height: u32, seed: u32) -> ImageRgb {
    let mut img = ImageRgb::filled(width, height, [0.0; 3]);
    for j in 0..height {
        for i in 0..width {
            let v = |k: u32| (((i * 7 + j * 13 + seed * 31 + k * 17) % 255) as f32) / 255.0;
            img.set(i, j, [v(0), v(1), v(2)]);
        }
    }
    // Round-trip through 8 bits so that comparisons after a PNG save are exact.
    ImageRgb::from_rgb8(width, height, &img.to_rgb8())
}

/// Writes a valid 16 x 12 dataset with 4 training and 2 validation frames, PNG images,
/// a background and `aud.npy` of shape [6, 16, 5]; returns its transforms files.
pub fn write_tiny_dataset(dir: &Path) -> (TransformsFile, TransformsFile) {
    let (w, h) = (16u32, 12u32);
    std::fs::create_dir_all(dir.join("head_imgs")).unwrap();
    pattern_image(w, h, 99)
        .save_png(&dir.join("bc.png"))
        .unwrap();
    let entries: Vec<FrameEntry> = (0..6)
        .map(|f| {
            let eye = Vec3::new(0.1 * f as f32, 0.05, 1.0);
            pattern_image(w, h, f)
                .save_png(&dir.join(format!("head_imgs/{f}.png")))
                .unwrap();
            FrameEntry {
                img_id: f as i64,
                aud_id: f as i64,
                transform_matrix: rows(&look_at(eye, Vec3::ZERO, Vec3::Y)),
                face_rect: Some(Rect {
                    x: 2,
                    y: 1,
                    w: 10,
                    h: 9,
                }),
                eye: Some(0.0),
            }
        })
        .collect();
    let make = |frames: &[FrameEntry]| TransformsFile {
        focal_len: 20.0,
        cx: 8.0,
        cy: 6.0,
        near: Some(0.8),
        far: Some(1.4),
        fps: Some(25.0),
        width: Some(w),
        height: Some(h),
        frames: frames.to_vec(),
    };
    let train = make(&entries[..4]);
    let val = make(&entries[4..]);
    train.save(&dir.join("transforms_train.json")).unwrap();
    val.save(&dir.join("transforms_val.json")).unwrap();
    let audio = AudioWindows {
        n_frames: 6,
        window: 16,
        n_features: 5,
        data: (0..6 * 16 * 5).map(|i| (i as f32 * 0.01).sin()).collect(),
    };
    save_audio_npy(&dir.join("aud.npy"), &audio).unwrap();
    (train, val)
}

/// Asserts that an error message is one line and names `needle` (a file name).
pub fn assert_one_line_naming(message: &str, needle: &str) {
    assert!(!message.contains('\n'), "error spans lines: {message:?}");
    assert!(
        message.contains(needle),
        "error {message:?} does not name {needle:?}"
    );
}

/// True under CI (`CI` set to anything but empty, `0` or `false`): a test whose tool
/// (Python, onnxruntime, ffmpeg) is missing then fails instead of skipping.
pub fn in_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| !v.is_empty() && v != "false" && v != "0")
}

/// A test's tool (Python, onnxruntime, ffmpeg) is missing, as `message` says: under CI
/// that fails the test; otherwise the test says it skips and gets `None`.
pub fn tool_missing<T>(message: impl std::fmt::Display) -> Option<T> {
    if in_ci() {
        panic!("{message}");
    }
    eprintln!("SKIPPED (CI is unset): {message}");
    None
}

/// A copy of the folder `from` at `to`, sub-folders included.
pub fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let dst = to.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            copy_dir(&e.path(), &dst);
        } else {
            std::fs::copy(e.path(), dst).unwrap();
        }
    }
}
