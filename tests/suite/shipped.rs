//! The model shipped in `models/demo/`: its card states its checksum, its size and every
//! metadata entry, and it renders finite frames from any WAV right after cloning, in tract
//! and, where onnxruntime is found, in ort too.

use std::path::{Path, PathBuf};

use nldf_core::audio::neighbourhood;
use nldf_core::metrics::psnr;
use nldf_export::read_model;
use nldf_infer::audio::windows_from_wav;
use nldf_infer::backend::{BackendKind, BackendOptions, backend_for};
use nldf_infer::frame::FrameRenderer;
use nldf_infer::poses::default_track;
use sha2::{Digest, Sha256};

use crate::util::{ort_available, write_test_wav};

fn shipped() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/demo")
}

/// The value of a card line `- key: `value``.
fn card_value(card: &str, key: &str) -> String {
    let prefix = format!("- {key}: `");
    card.lines()
        .find_map(|l| l.trim().strip_prefix(&prefix))
        .and_then(|rest| rest.split('`').next())
        .unwrap_or_else(|| panic!("the model card has no `{prefix}...` line"))
        .to_string()
}

#[test]
fn the_shipped_model_matches_its_card_and_renders_finite_frames() {
    let dir = shipped();
    let card = std::fs::read_to_string(dir.join("README.md")).unwrap();
    let path = dir.join("model.onnx");
    let bytes = std::fs::read(&path).unwrap();
    let digest: String = Sha256::digest(&bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    assert_eq!(digest, card_value(&card, "sha256"), "model.onnx's checksum");
    assert_eq!(bytes.len().to_string(), card_value(&card, "bytes"));
    let model = read_model(&path).unwrap();
    // Every metadata entry but the embedded background is in the card's table, verbatim.
    let mut listed = 0;
    for entry in &model.proto.metadata_props {
        let (key, value) = (
            entry.key.as_deref().unwrap_or_default(),
            entry.value.as_deref().unwrap_or_default(),
        );
        if key == nldf_export::contract::keys::BACKGROUND_FILE || value.len() > 200 {
            continue;
        }
        let row = format!("| `{key}` | `{value}` |");
        assert!(card.contains(&row), "the card lacks the row {row}");
        listed += 1;
    }
    assert!(listed >= 20, "{listed} metadata rows");

    // Any WAV renders: finite frames that show the head, alike in both runtimes.
    let tmp = tempfile::tempdir().unwrap();
    let wav = tmp.path().join("speech.wav");
    write_test_wav(&wav, 1.0);
    let info = &model.info;
    let windows = windows_from_wav(info, &path, &wav).unwrap();
    let track = default_track(info, 3);
    let mut kinds = vec![BackendKind::Tract];
    if ort_available() {
        kinds.push(BackendKind::Ort);
    }
    let mut frames = Vec::new();
    for kind in kinds {
        let backend = backend_for(&model, kind, BackendOptions::default()).unwrap();
        let mut renderer = FrameRenderer::new(backend, None).unwrap();
        for (f, c2w) in track.iter().enumerate() {
            let audio = neighbourhood(&windows, 10 + f, info.audio.att_frames);
            let frame = renderer.render(*c2w, &audio).unwrap();
            assert_eq!(frame.image.non_finite_values(), 0, "{kind:?} frame {f}");
            assert!(
                frame.head_pixels > 100,
                "{kind:?} frame {f} misses the head"
            );
            frames.push(frame.image);
        }
    }
    if frames.len() == 6 {
        for f in 0..3 {
            let p = psnr(&frames[f], &frames[f + 3]).unwrap();
            assert!(p > 50.0, "tract and ort differ on frame {f}: {p:.1} dB");
        }
    }
}
