//! AD-NeRF datasets: round trip, AD-NeRF's own fields, and malformed files.

use std::path::Path;

use nldf_core::dataset::{Dataset, Split, load_audio_npy};
use nldf_tests::{assert_one_line_naming, pattern_image, write_tiny_dataset};

#[test]
fn dataset_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let (train, val) = write_tiny_dataset(dir.path());
    let ds = Dataset::load(dir.path()).unwrap();
    assert_eq!((ds.intrinsics.width, ds.intrinsics.height), (16, 12));
    assert_eq!(ds.intrinsics.focal, 20.0);
    assert_eq!((ds.near, ds.far, ds.fps), (0.8, 1.4, 25.0));
    assert_eq!(ds.frames(Split::Train).len(), 4);
    assert_eq!(ds.frames(Split::Val).len(), 2);
    assert_eq!(ds.background, pattern_image(16, 12, 99));
    assert_eq!(
        (ds.audio.n_frames, ds.audio.window, ds.audio.n_features),
        (6, 16, 5)
    );
    assert_eq!(ds.audio.data[7], (7.0f32 * 0.01).sin());
    for (frame, entry) in ds
        .train
        .iter()
        .zip(&train.frames)
        .chain(ds.val.iter().zip(&val.frames))
    {
        assert_eq!(frame.img_id, entry.img_id);
        assert_eq!(nldf_tests::rows(&frame.c2w), entry.transform_matrix);
        assert_eq!(
            ds.load_image(frame).unwrap(),
            pattern_image(16, 12, frame.img_id as u32)
        );
        assert_eq!(frame.face_rect, entry.face_rect.unwrap());
    }
}

#[test]
fn ad_nerf_fields_alone_load_with_jpg_frames() {
    let dir = tempfile::tempdir().unwrap();
    write_tiny_dataset(dir.path());
    // Rewrite the transforms as AD-NeRF writes them: only its own fields, no near/far, and
    // the frames as JPEG under ori_imgs/.
    let matrix =
        "[[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 1.1], [0.0, 0.0, 0.0, 1.0]]";
    let frame = |id: u32| {
        format!(
            r#"{{"img_id": {id}, "aud_id": {id}, "transform_matrix": {matrix}, "face_rect": [3, 2, 8, 8]}}"#
        )
    };
    let train = format!(
        r#"{{"focal_len": 20.0, "cx": 8.0, "cy": 6.0, "frames": [{}, {}]}}"#,
        frame(0),
        frame(1)
    );
    let val = format!(
        r#"{{"focal_len": 20.0, "cx": 8.0, "cy": 6.0, "frames": [{}]}}"#,
        frame(2)
    );
    std::fs::write(dir.path().join("transforms_train.json"), train).unwrap();
    std::fs::write(dir.path().join("transforms_val.json"), val).unwrap();
    std::fs::remove_dir_all(dir.path().join("head_imgs")).unwrap();
    std::fs::create_dir(dir.path().join("ori_imgs")).unwrap();
    for id in 0..3 {
        let img = pattern_image(16, 12, id);
        image::RgbImage::from_raw(16, 12, img.to_rgb8())
            .unwrap()
            .save(dir.path().join(format!("ori_imgs/{id}.jpg")))
            .unwrap();
    }
    let ds = Dataset::load(dir.path()).unwrap();
    assert_eq!(ds.train.len(), 2);
    // AD-NeRF's bounds: mean camera distance 1.1 minus 0.2 and plus 0.4.
    assert!((ds.near - 0.9).abs() < 1e-6 && (ds.far - 1.5).abs() < 1e-6);
    let img = ds.load_image(&ds.val[0]).unwrap();
    assert_eq!((img.width, img.height), (16, 12));
}

/// Breaks a fresh tiny dataset with `damage`, then expects loading (and decoding every
/// frame) to fail with one line naming `file`.
fn expect_rejected(file: &str, damage: impl FnOnce(&Path)) {
    let dir = tempfile::tempdir().unwrap();
    write_tiny_dataset(dir.path());
    damage(dir.path());
    let result = Dataset::load(dir.path()).and_then(|ds| {
        for f in ds.train.iter().chain(&ds.val) {
            ds.load_image(f)?;
        }
        Ok(ds)
    });
    let err = result.expect_err(&format!("damaged {file} was accepted"));
    assert_one_line_naming(&err.to_string(), file);
}

fn edit_json(dir: &Path, file: &str, edit: impl FnOnce(&mut serde_json::Value)) {
    let path = dir.join(file);
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    edit(&mut v);
    std::fs::write(path, serde_json::to_string(&v).unwrap()).unwrap();
}

fn write_npy(dir: &Path, shape: &[u64], data: Vec<f32>) {
    crate::util::write_npy(&dir.join("aud.npy"), shape, &data);
}

#[test]
fn missing_frame_is_rejected() {
    expect_rejected("head_imgs/2.png", |d| {
        std::fs::remove_file(d.join("head_imgs/2.png")).unwrap()
    });
}

#[test]
fn truncated_transforms_json_is_rejected() {
    expect_rejected("transforms_train.json", |d| {
        let p = d.join("transforms_train.json");
        let text = std::fs::read_to_string(&p).unwrap();
        std::fs::write(&p, &text[..text.len() / 2]).unwrap();
    });
}

#[test]
fn missing_val_transforms_is_rejected() {
    expect_rejected("transforms_val.json", |d| {
        std::fs::remove_file(d.join("transforms_val.json")).unwrap()
    });
}

#[test]
fn nan_in_matrix_is_rejected() {
    expect_rejected("transforms_train.json", |d| {
        let p = d.join("transforms_train.json");
        let text = std::fs::read_to_string(&p)
            .unwrap()
            .replacen("1.0", "NaN", 1);
        std::fs::write(&p, text).unwrap();
    });
}

#[test]
fn non_rigid_matrix_is_rejected() {
    expect_rejected("transforms_val.json", |d| {
        edit_json(d, "transforms_val.json", |v| {
            v["frames"][1]["transform_matrix"][0][0] = serde_json::json!(2.0);
        })
    });
}

#[test]
fn matrix_with_three_rows_is_rejected() {
    expect_rejected("transforms_train.json", |d| {
        edit_json(d, "transforms_train.json", |v| {
            v["frames"][0]["transform_matrix"]
                .as_array_mut()
                .unwrap()
                .pop();
        })
    });
}

#[test]
fn audio_shorter_than_the_frames_is_rejected() {
    expect_rejected("aud.npy", |d| {
        write_npy(d, &[4, 16, 5], vec![0.0; 4 * 16 * 5])
    });
}

#[test]
fn audio_of_wrong_shape_is_rejected() {
    expect_rejected("aud.npy", |d| {
        write_npy(d, &[6, 8, 5], vec![0.0; 6 * 8 * 5])
    });
}

#[test]
fn truncated_audio_is_rejected() {
    expect_rejected("aud.npy", |d| {
        let p = d.join("aud.npy");
        let bytes = std::fs::read(&p).unwrap();
        std::fs::write(&p, &bytes[..bytes.len() - 40]).unwrap();
    });
}

#[test]
fn integer_audio_is_rejected() {
    expect_rejected("aud.npy", |d| {
        use npyz::WriterBuilder;
        let mut buf = Vec::new();
        let mut w = npyz::WriteOptions::<i32>::new()
            .default_dtype()
            .shape(&[6, 16, 5])
            .writer(&mut buf)
            .begin_nd()
            .unwrap();
        w.extend(vec![0i32; 6 * 16 * 5]).unwrap();
        w.finish().unwrap();
        std::fs::write(d.join("aud.npy"), buf).unwrap();
    });
}

#[test]
fn non_finite_audio_is_rejected() {
    expect_rejected("aud.npy", |d| {
        let mut data = vec![0.0f32; 6 * 16 * 5];
        data[100] = f32::INFINITY;
        write_npy(d, &[6, 16, 5], data)
    });
}

#[test]
fn audio_that_is_not_npy_is_rejected() {
    expect_rejected("aud.npy", |d| {
        std::fs::write(d.join("aud.npy"), b"RIFF....WAVEfmt ").unwrap()
    });
}

#[test]
fn missing_background_is_rejected() {
    expect_rejected("bc.png", |d| {
        std::fs::remove_file(d.join("bc.png")).unwrap()
    });
}

#[test]
fn frame_of_wrong_size_is_rejected() {
    expect_rejected("head_imgs/3.png", |d| {
        pattern_image(8, 8, 3)
            .save_png(&d.join("head_imgs/3.png"))
            .unwrap()
    });
}

#[test]
fn corrupt_png_frame_is_rejected() {
    expect_rejected("head_imgs/1.png", |d| {
        let p = d.join("head_imgs/1.png");
        let bytes = std::fs::read(&p).unwrap();
        std::fs::write(&p, &bytes[..bytes.len() / 2]).unwrap();
    });
}

#[test]
fn face_rect_outside_the_image_is_rejected() {
    expect_rejected("transforms_train.json", |d| {
        edit_json(d, "transforms_train.json", |v| {
            v["frames"][2]["face_rect"] = serde_json::json!([100, 100, 5, 5]);
        })
    });
}

#[test]
fn inverted_bounds_are_rejected() {
    expect_rejected("transforms_train.json", |d| {
        edit_json(d, "transforms_train.json", |v| {
            v["near"] = serde_json::json!(2.0);
        })
    });
}

#[test]
fn image_size_disagreeing_with_json_is_rejected() {
    expect_rejected("transforms_val.json", |d| {
        edit_json(d, "transforms_val.json", |v| {
            v["width"] = serde_json::json!(32);
        })
    });
}

#[test]
fn float64_audio_loads_as_f32() {
    use npyz::WriterBuilder;
    let dir = tempfile::tempdir().unwrap();
    let mut buf = Vec::new();
    let mut w = npyz::WriteOptions::<f64>::new()
        .default_dtype()
        .shape(&[2, 16, 3])
        .writer(&mut buf)
        .begin_nd()
        .unwrap();
    w.extend((0..96).map(|i| i as f64 * 0.5)).unwrap();
    w.finish().unwrap();
    let p = dir.path().join("aud.npy");
    std::fs::write(&p, buf).unwrap();
    let a = load_audio_npy(&p).unwrap();
    assert_eq!((a.n_frames, a.window, a.n_features), (2, 16, 3));
    assert_eq!(a.data[95], 47.5);
}

#[test]
fn an_npy_header_whose_shape_overflows_is_refused_in_one_line() {
    // Valid v1.0 headers whose dimensions multiply past u64 (also behind a zero dimension,
    // which npyz's strides multiply past): the npy reader must answer with an error, not an
    // arithmetic overflow.
    for shape in [
        "(4294967296, 16, 4294967296)",
        "(0, 8589934592, 8589934592)",
    ] {
        overflowing_npy_is_refused(shape);
    }
}

fn overflowing_npy_is_refused(shape: &str) {
    let dict = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {shape}, }}");
    let mut header = dict.to_string();
    while !(10 + header.len() + 1).is_multiple_of(64) {
        header.push(' ');
    }
    header.push('\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
    bytes.extend_from_slice(header.as_bytes());
    bytes.extend_from_slice(&[0u8; 64]);
    let err = nldf_core::dataset::parse_audio_npy(Path::new("aud.npy"), &bytes).unwrap_err();
    assert_one_line_naming(&err.to_string(), "aud.npy");
    assert!(err.to_string().contains("holds more values"), "{err}");
}
