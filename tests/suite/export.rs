//! ONNX export: a seeded tiny student is exported and must agree with the candle reference
//! (`Student::render_rays`) in tract and in Python onnxruntime, pass `onnx.checker` with
//! `full_check`, render the same frame in `examples/onnxruntime_render.py` as in Rust, and
//! every bad model file must get a one-line error naming it.

use std::path::Path;
use std::process::Command;

use crate::util::{
    PYTHON_PARITY, Run, TOL, candle_frame, candle_render, configs, foreign_model, max_diff, python,
    random_audio, random_rays, ray_background, read_npy, run_python, tensor_shapes, write_npy,
    write_run,
};
use glam::Mat4;
use nldf_core::audio::neighbourhood;
use nldf_core::camera::Camera;
use nldf_core::dataset::save_audio_npy;
use nldf_core::image::ImageRgb;
use nldf_core::rays::{Rays, head_rays};
use nldf_core::render_spec::BACKGROUND_FILE;
use nldf_export::{WeightType, export_student};
use nldf_model::contract::{self, ModelInfo};
use nldf_model::onnx::StringStringEntryProto;
use nldf_model::{Error, read_model};
use nldf_train::networks::student::StudentConfig;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The model at `path` run by tract with a concrete ray count: pixels (composited over
/// [`ray_background`]) and segments, flat.
fn tract_render(
    path: &Path,
    rays: &Rays,
    audio: &[f32],
    shape: [usize; 3],
) -> (Vec<f32>, Vec<f32>) {
    use tract_onnx::prelude::*;
    let n = rays.len();
    let model = tract_onnx::onnx()
        .model_for_path(path)
        .unwrap()
        .with_input_fact(0, f32::fact([n, 3]).into())
        .unwrap()
        .with_input_fact(1, f32::fact([n, 3]).into())
        .unwrap()
        .with_input_fact(3, f32::fact([n, 3]).into())
        .unwrap();
    let model = model.into_optimized().unwrap().into_runnable().unwrap();
    let origins = Tensor::from_shape(&[n, 3], &rays.origins).unwrap();
    let directions = Tensor::from_shape(&[n, 3], &rays.directions).unwrap();
    let audio = Tensor::from_shape(&shape, audio).unwrap();
    let background = Tensor::from_shape(&[n, 3], &ray_background(n)).unwrap();
    let inputs: TVec<TValue> = tvec!(
        origins.into(),
        directions.into(),
        audio.into(),
        background.into()
    );
    let out = model.run(inputs).unwrap();
    let flat = |t: &TValue| -> Vec<f32> {
        t.to_plain_array_view::<f32>()
            .unwrap()
            .iter()
            .copied()
            .collect()
    };
    (flat(&out[0]), flat(&out[1]))
}

/// The model at `path` (exported from `run`) in tract against candle on `rays`: the largest
/// pixel and segment differences, and tract's pixels.
fn tract_against_candle(
    run: &Run,
    path: &Path,
    cfg: &StudentConfig,
    rays: &Rays,
    audio: &[f32],
) -> (f32, f32, Vec<f32>) {
    let (want_rgb, want_seg) = candle_render(run, rays, audio);
    let shape = [cfg.audio.att_frames, cfg.audio.window, cfg.audio.n_features];
    let (rgb, seg) = tract_render(path, rays, audio, shape);
    (max_diff(&rgb, &want_rgb), max_diff(&seg, &want_seg), rgb)
}

#[test]
fn export_tract_matches_candle_on_10000_rays() {
    for (c, cfg) in configs().into_iter().enumerate() {
        let run = write_run(&cfg, 11 + c as u64);
        let path = run.export(WeightType::F32);
        let rays = random_rays(10_000, 3);
        let audio = neighbourhood(&random_audio(&cfg, 12, 4), 5, cfg.audio.att_frames);
        let (d_rgb, d_seg, rgb) = tract_against_candle(&run, &path, &cfg, &rays, &audio);
        println!(
            "config {c} (K {}, L {}, attention {}): tract vs candle, 10000 rays: max |rgb diff| \
             {d_rgb:.2e}, max |segment diff| {d_seg:.2e}",
            cfg.beam.n_points, cfg.beam.n_freqs, cfg.attention
        );
        assert!(d_rgb <= TOL && d_seg <= TOL, "{d_rgb} {d_seg}");
        // The outputs must depend on the audio: another frame gives other colours.
        let other = neighbourhood(&random_audio(&cfg, 12, 4), 9, cfg.audio.att_frames);
        let shape = [cfg.audio.att_frames, cfg.audio.window, cfg.audio.n_features];
        let (rgb2, _) = tract_render(&path, &rays, &other, shape);
        assert!(
            max_diff(&rgb, &rgb2) > 1e-5,
            "audio does not reach the output"
        );
    }
}

#[test]
fn export_fp16_weights_match_candle_with_rounded_weights() {
    let cfg = StudentConfig::tiny();
    let run = write_run(&cfg, 21);
    let f32_path = run.export(WeightType::F32);
    let f16_path = run.export(WeightType::F16);
    let (f32_len, f16_len) = (
        std::fs::metadata(&f32_path).unwrap().len(),
        std::fs::metadata(&f16_path).unwrap().len(),
    );
    assert!(
        (f16_len as f64) < 0.7 * f32_len as f64,
        "{f16_len} vs {f32_len}"
    );
    run.round_weights_to_f16();
    let rays = random_rays(2000, 5);
    let audio = neighbourhood(&random_audio(&cfg, 10, 6), 3, cfg.audio.att_frames);
    let (want_rgb, want_seg) = candle_render(&run, &rays, &audio);
    let shape = [cfg.audio.att_frames, cfg.audio.window, cfg.audio.n_features];
    let (rgb, seg) = tract_render(&f16_path, &rays, &audio, shape);
    let (d_rgb, d_seg) = (max_diff(&rgb, &want_rgb), max_diff(&seg, &want_seg));
    println!("fp16 weights: tract vs candle with f16-rounded weights: {d_rgb:.2e} {d_seg:.2e}");
    assert!(d_rgb <= TOL && d_seg <= TOL, "{d_rgb} {d_seg}");
}

#[test]
fn export_writes_the_contract() {
    let cfg = StudentConfig::tiny();
    let run = write_run(&cfg, 31);
    let path = run.export(WeightType::F32);
    let model = read_model(&path).unwrap();
    assert_eq!(model.proto.ir_version, Some(contract::IR_VERSION));
    const { assert!(contract::IR_VERSION <= 9) };
    let opset = &model.proto.opset_import;
    assert_eq!(opset.len(), 1);
    assert_eq!(opset[0].version, Some(17));
    let graph = model.proto.graph.as_ref().unwrap();
    let names = |v: &[nldf_model::onnx::ValueInfoProto]| -> Vec<String> {
        v.iter().map(|i| i.name.clone().unwrap()).collect()
    };
    // The student composites over a background input.
    assert_eq!(
        names(&graph.input),
        ["rays_o", "rays_d", "audio", "background"]
    );
    assert_eq!(names(&graph.output), ["rgb", "segments", "opacity"]);
    // Initializer names are the checkpoint's weight paths.
    let inits: Vec<&str> = graph
        .initializer
        .iter()
        .filter_map(|t| t.name.as_deref())
        .collect();
    for name in [
        "mlp.body.1.fc2.weight",
        "audio.att.attention.bias",
        "audio.net.convs.3.weight",
    ] {
        assert!(inits.contains(&name), "{name} missing from {inits:?}");
    }
    let info = &model.info;
    assert_eq!(info.spec, run.spec);
    assert_eq!(info.step, 7);
    assert_eq!(
        (info.beam.n_points, info.beam.n_freqs, info.segments),
        (4, 4, 4)
    );
    assert_eq!(info.audio.shape(), [8, 16, 29]);
    assert!(info.audio.attention);
    let background = image::load_from_memory(&info.background_png)
        .unwrap()
        .to_rgb8();
    let want = ImageRgb::load(&run.student_dir().join(BACKGROUND_FILE)).unwrap();
    assert_eq!(background.as_raw(), &want.to_rgb8());
}

#[test]
fn export_bad_model_files_get_one_line_errors_naming_them() {
    let cfg = StudentConfig::tiny();
    let run = write_run(&cfg, 41);
    let good = std::fs::read(run.export(WeightType::F32)).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let check = |name: &str, bytes: &[u8]| -> Error {
        let path = dir.path().join(name);
        std::fs::write(&path, bytes).unwrap();
        let Err(err) = read_model(&path) else {
            panic!("{name} was accepted")
        };
        let msg = err.to_string();
        assert!(!msg.contains('\n'), "{name}: {msg}");
        assert!(msg.contains(&path.display().to_string()), "{name}: {msg}");
        println!("{name}: {msg}");
        err
    };
    // Truncated anywhere: inside the graph, inside the metadata, one byte short.
    for cut in [
        1,
        10,
        good.len() / 3,
        good.len() / 2,
        good.len() - 1000,
        good.len() - 1,
    ] {
        let err = check(&format!("cut_{cut}.onnx"), &good[..cut]);
        assert!(matches!(err, Error::Corrupt { .. }), "cut {cut}: {err}");
    }
    // Corrupt: bytes overwritten in the middle, random bytes, an empty file, a PNG.
    let mut flipped = good.clone();
    let mid = flipped.len() / 2;
    for b in &mut flipped[mid..mid + 64] {
        *b = 0xff;
    }
    assert!(matches!(
        check("flipped.onnx", &flipped),
        Error::Corrupt { .. }
    ));
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let noise: Vec<u8> = (0..4096).map(|_| rng.random()).collect();
    let err = check("noise.onnx", &noise);
    assert!(
        matches!(err, Error::Corrupt { .. } | Error::Foreign { .. }),
        "{err}"
    );
    assert!(matches!(check("empty.onnx", &[]), Error::Corrupt { .. }));
    let png = std::fs::read(run.student_dir().join(BACKGROUND_FILE)).unwrap();
    let err = check("image.onnx", &png);
    assert!(
        matches!(err, Error::Corrupt { .. } | Error::Foreign { .. }),
        "{err}"
    );
    // Foreign: a valid ONNX model without nldf metadata, or another format's.
    assert!(matches!(
        check("foreign.onnx", &foreign_model(vec![])),
        Error::Foreign { .. }
    ));
    let other = vec![StringStringEntryProto {
        key: Some(contract::keys::FORMAT.to_string()),
        value: Some("something-else".to_string()),
    }];
    assert!(matches!(
        check("other.onnx", &foreign_model(other)),
        Error::Foreign { .. }
    ));
    // nldf metadata on a graph without the contract's inputs.
    let info = read_model(&run.root.join("model.onnx")).unwrap().info;
    let err = check("wrong_graph.onnx", &foreign_model(info.to_metadata()));
    assert!(matches!(err, Error::Corrupt { .. }), "{err}");
    // A missing file.
    let missing = dir.path().join("missing.onnx");
    let msg = read_model(&missing).unwrap_err().to_string();
    assert!(msg.contains("missing.onnx") && !msg.contains('\n'), "{msg}");
}

#[test]
fn export_bad_checkpoints_name_their_file() {
    let cfg = StudentConfig::tiny();
    let run = write_run(&cfg, 51);
    let out = run.root.join("x.onnx");
    // A config whose width disagrees with the weights.
    let mut wrong = cfg.clone();
    wrong.width = 16;
    let config = serde_json::json!({ "model": wrong });
    std::fs::write(run.student_dir().join("config.json"), config.to_string()).unwrap();
    let msg = export_student(&run.student_dir(), &out, WeightType::F32)
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("model.safetensors") && msg.contains("shape"),
        "{msg}"
    );
    // No config at all.
    std::fs::remove_file(run.student_dir().join("config.json")).unwrap();
    let msg = export_student(&run.student_dir(), &out, WeightType::F32)
        .unwrap_err()
        .to_string();
    assert!(msg.contains("config.json"), "{msg}");
    assert!(!out.exists());
}

#[test]
fn export_passes_onnx_checker_and_python_onnxruntime_matches_candle() {
    let Some(python) = python() else { return };
    for (c, cfg) in configs().into_iter().enumerate() {
        for weights in [WeightType::F32, WeightType::F16] {
            let run = write_run(&cfg, 61 + c as u64);
            let path = run.export(weights);
            if weights == WeightType::F16 {
                run.round_weights_to_f16();
            }
            let rays = random_rays(10_000, 7);
            let audio = neighbourhood(&random_audio(&cfg, 9, 8), 0, cfg.audio.att_frames);
            let folder = run.root.join("io");
            std::fs::create_dir_all(&folder).unwrap();
            let n = rays.len() as u64;
            write_npy(&folder.join("rays_o.npy"), &[n, 3], &rays.origins);
            write_npy(&folder.join("rays_d.npy"), &[n, 3], &rays.directions);
            write_npy(
                &folder.join("background.npy"),
                &[n, 3],
                &ray_background(rays.len()),
            );
            let a = &cfg.audio;
            let shape = [a.att_frames as u64, a.window as u64, a.n_features as u64];
            write_npy(&folder.join("audio.npy"), &shape, &audio);
            let report = run_python(
                &python,
                &[
                    "-c",
                    PYTHON_PARITY,
                    path.to_str().unwrap(),
                    folder.to_str().unwrap(),
                ],
            );
            let report: serde_json::Value = serde_json::from_str(report.trim()).unwrap();
            assert_eq!(report["ir_version"], 9);
            assert_eq!(report["opset"], 17);
            assert_eq!(report["rays_o"], serde_json::json!(["n_rays", 3]));
            let (want_rgb, want_seg) = candle_render(&run, &rays, &audio);
            let (rgb_shape, rgb) = read_npy(&folder.join("rgb.npy"));
            let (seg_shape, seg) = read_npy(&folder.join("segments.npy"));
            assert_eq!(rgb_shape, [n, 3]);
            assert_eq!(seg_shape, [n, cfg.segments as u64, 3]);
            let (d_rgb, d_seg) = (max_diff(&rgb, &want_rgb), max_diff(&seg, &want_seg));
            println!(
                "config {c}, {weights:?}: onnxruntime {} vs candle, 10000 rays: max |rgb diff| \
                 {d_rgb:.2e}, max |segment diff| {d_seg:.2e}",
                report["onnxruntime"]
            );
            assert!(d_rgb <= TOL && d_seg <= TOL, "{d_rgb} {d_seg}");
        }
    }
}

/// The Rust reference frame from the model's default pose; the camera sees both the head
/// and the background.
fn reference_frame(run: &Run, audio: &[f32]) -> Vec<f32> {
    let spec = &run.spec;
    let c2w = Mat4::from_cols_array_2d(&spec.default_pose).transpose();
    let background = ImageRgb::load(&run.student_dir().join(&spec.background)).unwrap();
    let head = head_rays(
        &Camera {
            intrinsics: spec.intrinsics,
            c2w,
        },
        &spec.head_range(),
    );
    assert!(
        !head.pixels.is_empty() && head.pixels.len() < spec.intrinsics.n_pixels(),
        "the test camera should see both head and background"
    );
    candle_frame(run, spec.intrinsics, c2w, audio, &background).data
}

#[test]
fn export_python_example_renders_the_rust_reference_frame() {
    let Some(python) = python() else { return };
    let cfg = StudentConfig::tiny();
    let run = write_run(&cfg, 71);
    let path = run.export(WeightType::F32);
    let track = random_audio(&cfg, 6, 9);
    let aud = run.root.join("aud.npy");
    save_audio_npy(&aud, &track).unwrap();
    let frame_index = 1;
    let want = reference_frame(
        &run,
        &neighbourhood(&track, frame_index, cfg.audio.att_frames),
    );
    let example = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/onnxruntime_render.py");
    let (out, png) = (run.root.join("frame.npy"), run.root.join("frame.png"));
    run_python(
        &python,
        &[
            example.to_str().unwrap(),
            path.to_str().unwrap(),
            "--audio",
            aud.to_str().unwrap(),
            "--frame",
            &frame_index.to_string(),
            "--out",
            out.to_str().unwrap(),
            "--png",
            png.to_str().unwrap(),
        ],
    );
    let (shape, got) = read_npy(&out);
    let k = run.spec.intrinsics;
    assert_eq!(shape, [k.height as u64, k.width as u64, 3]);
    let d = max_diff(&got, &want);
    println!(
        "python example frame vs Rust reference ({}x{}): max |diff| {d:.2e}",
        k.width, k.height
    );
    assert!(d <= TOL, "{d}");
    let img = ImageRgb::load(&png).unwrap();
    assert_eq!((img.width, img.height), (k.width, k.height));
    // The example also refuses a model that nldf did not write.
    let foreign = run.root.join("foreign.onnx");
    std::fs::write(&foreign, foreign_model(vec![])).unwrap();
    let status = Command::new(&python)
        .args([example.to_str().unwrap(), foreign.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(!status.status.success());
    assert!(String::from_utf8_lossy(&status.stderr).contains("not an nldf model"));
}

#[test]
fn export_metadata_round_trips_and_rejects_disagreement() {
    let cfg = StudentConfig::tiny();
    let run = write_run(&cfg, 81);
    let path = run.export(WeightType::F32);
    let info = read_model(&path).unwrap().info;
    let props = info.to_metadata();
    assert_eq!(props[0].key.as_deref(), Some(contract::keys::FORMAT));
    assert_eq!(ModelInfo::from_metadata(&props).unwrap(), info);
    let mut bad = props.clone();
    for p in &mut bad {
        if p.key.as_deref() == Some(contract::keys::FOCAL) {
            p.value = Some("12.5".into());
        }
    }
    let err = ModelInfo::from_metadata(&bad).unwrap_err().to_string();
    assert!(err.contains(contract::keys::FOCAL), "{err}");
    let missing: Vec<_> = props
        .iter()
        .filter(|p| p.key.as_deref() != Some(contract::keys::NEAR))
        .cloned()
        .collect();
    let err = ModelInfo::from_metadata(&missing).unwrap_err().to_string();
    assert!(err.contains(contract::keys::NEAR), "{err}");
}

/// The student's networks are described once (`nldf_core::student_network`: the MLP's
/// `MlpLayout`, the audio encoder's `AudioLayout`): the candle builders' weights are exactly
/// the descriptions' tensors, the ONNX builder's graph computes each described layer under
/// its name with the weights of that name, and the graph so built renders what candle
/// renders.
#[test]
fn the_student_graph_follows_the_shared_network_description() {
    use std::collections::BTreeMap;

    use nldf_core::student_network::{AudioLayout, MlpLayout};

    for (c, cfg) in configs().into_iter().enumerate() {
        let layout = MlpLayout::of(&cfg);
        let run = write_run(&cfg, 21 + c as u64);
        // candle: the checkpoint's MLP tensors are the description's, name for name.
        let built = tensor_shapes(&run.student_dir().join("model.safetensors"));
        let audio = AudioLayout::of(&cfg.audio);
        let described: BTreeMap<String, Vec<usize>> = layout
            .layers()
            .iter()
            .flat_map(|l| l.tensors())
            .chain(audio.tensors())
            .collect();
        assert_eq!(
            built, described,
            "config {c}: candle's student is not the description"
        );
        // ONNX: a node and the weights of each described layer (the input layer's weight
        // split into its beam and audio columns).
        let path = run.export(WeightType::F32);
        let graph = read_model(&path).unwrap().proto.graph.unwrap();
        let nodes: Vec<&str> = graph
            .node
            .iter()
            .filter_map(|n| n.name.as_deref())
            .collect();
        let weights: BTreeMap<&str, Vec<i64>> = graph
            .initializer
            .iter()
            .filter_map(|t| Some((t.name.as_deref()?, t.dims.clone())))
            .collect();
        let convs = audio.net_convs.iter().chain(&audio.att_convs);
        for conv in convs.filter(|l| cfg.attention || l.prefix == "audio.net") {
            let name = conv.path();
            assert!(nodes.contains(&name.as_str()), "config {c}: no node {name}");
            let w = weights.get(format!("{name}.weight").as_str());
            let want = vec![conv.c_out as i64, conv.c_in as i64, conv.kernel as i64];
            assert_eq!(w, Some(&want), "config {c}: {name}.weight");
        }
        for layer in layout.layers() {
            let name = layer.path();
            assert!(nodes.contains(&name.as_str()), "config {c}: no node {name}");
            let bias = weights.get(format!("{name}.bias").as_str());
            assert_eq!(
                bias,
                Some(&vec![layer.fan_out as i64]),
                "config {c}: {name}.bias"
            );
            if layer.name != "input" {
                let w = weights.get(format!("{name}.weight").as_str());
                let want = vec![layer.fan_out as i64, layer.fan_in as i64];
                assert_eq!(w, Some(&want), "config {c}: {name}.weight");
            }
        }
        // And the graph renders what candle renders.
        let rays = random_rays(500, 5);
        let audio = neighbourhood(&random_audio(&cfg, 12, 4), 3, cfg.audio.att_frames);
        let (d_rgb, d_seg, _) = tract_against_candle(&run, &path, &cfg, &rays, &audio);
        assert!(d_rgb <= TOL && d_seg <= TOL, "config {c}: {d_rgb} {d_seg}");
    }
}

/// One version check when a model or a checkpoint loads: a model of contract 3, one
/// without opacity and one without a beam anchor, and a checkpoint without this build's
/// checkpoint version, are each refused as made by an older nldf; a config written before
/// version 2 reads when its retired switches are on, and is refused when one is off.
#[test]
fn models_checkpoints_and_configs_of_an_older_nldf_are_refused_with_one_error() {
    use nldf_core::run_files::{CHECKPOINT_VERSION_KEY, MODEL_FILE};

    let cfg = StudentConfig::tiny();
    let run = write_run(&cfg, 83);
    let path = run.export(WeightType::F32);
    let model = read_model(&path).unwrap();
    let with = |key: &str, value: &str| -> Vec<StringStringEntryProto> {
        let mut props = model.info.to_metadata();
        for p in &mut props {
            if p.key.as_deref() == Some(key) {
                p.value = Some(value.to_string());
            }
        }
        props
    };
    let version = contract::keys::CONTRACT;
    for (key, value, what) in [
        (version, "3", "contract version 3"),
        (version, "2", "contract version 2"),
        (contract::keys::OPACITY, "false", "no opacity"),
        (contract::keys::BEAM_ANCHOR, "null", "no beam anchor"),
    ] {
        let err = ModelInfo::from_metadata(&with(key, value))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("made by an older nldf") && err.contains(what),
            "{key} = {value}: {err}"
        );
        assert!(err.contains("train again or re-export"), "{err}");
    }
    // Through a file: the error names it.
    let mut older = model.proto.clone();
    older.metadata_props = with(version, "3");
    let older_path = run.root.join("older.onnx");
    std::fs::write(&older_path, prost::Message::encode_to_vec(&older)).unwrap();
    let err = read_model(&older_path).unwrap_err();
    assert!(matches!(err, Error::Older { .. }), "{err:?}");
    assert!(err.to_string().contains("older.onnx"), "{err}");
    let newer = ModelInfo::from_metadata(&with(version, "7"))
        .unwrap_err()
        .to_string();
    assert!(newer.contains("newer nldf"), "{newer}");

    // A checkpoint without the version: export and the trainer's loader refuse it.
    let weights = run.student_dir().join(MODEL_FILE);
    let (tensors, mut meta) = nldf_train::trainers::checkpoint::load_tensors(&weights).unwrap();
    assert!(meta.remove(CHECKPOINT_VERSION_KEY).is_some());
    nldf_train::trainers::checkpoint::save_tensors(&weights, &tensors, meta).unwrap();
    let err = export_student(
        &run.student_dir(),
        &run.root.join("v1.onnx"),
        WeightType::F32,
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("model.safetensors") && err.contains("checkpoint version 1"),
        "{err}"
    );
    assert!(err.contains("made by an older nldf"), "{err}");
    assert!(!run.root.join("v1.onnx").exists());
    let (varmap, vb) = nldf_train::networks::nn::new_varmap();
    nldf_train::networks::student::student(&run.student.cfg, vb).unwrap();
    let err = nldf_train::trainers::checkpoint::open_checkpoint(&run.student_dir(), &varmap, None)
        .unwrap_err()
        .to_string();
    assert!(err.contains("checkpoint version 1"), "{err}");

    // Configs: the retired switches read when on, never written, refused when off.
    let mut json = serde_json::to_value(&cfg).unwrap();
    assert!(json.get("opacity").is_none() && json.get("anchor_beams").is_none());
    json["opacity"] = true.into();
    json["anchor_beams"] = true.into();
    let read: StudentConfig = serde_json::from_value(json.clone()).unwrap();
    assert_eq!(read, cfg);
    for key in ["opacity", "anchor_beams"] {
        let mut off = json.clone();
        off[key] = false.into();
        let err = serde_json::from_value::<StudentConfig>(off)
            .unwrap_err()
            .to_string();
        assert!(err.contains("older nldf"), "{key}: {err}");
    }
}

/// A short-lookahead student (`model.audio.ahead`) reads only the first
/// `window / 2 + ahead` rows of its centre window, in candle and in the exported graph alike:
/// changing the later rows or the other windows changes nothing, changing a row it reads
/// changes the colours, and the graph matches candle. Its metadata says how many rows it
/// reads past the centre.
#[test]
fn export_a_short_lookahead_student_reads_only_its_rows_as_candle_does() {
    let mut cfg = StudentConfig::tiny();
    cfg.attention = false;
    cfg.audio.ahead = Some(3);
    let rows = cfg.audio.rows_read();
    assert_eq!(rows, 11);
    let run = write_run(&cfg, 31);
    let path = run.export(WeightType::F32);
    let info = read_model(&path).unwrap().info;
    assert_eq!(info.audio.ahead, Some(3));
    assert_eq!(info.audio.rows_read(), rows);
    let rays = random_rays(2000, 5);
    let a = &cfg.audio;
    let audio = neighbourhood(&random_audio(&cfg, 10, 6), 3, a.att_frames);
    let (d_rgb, d_seg, rgb) = tract_against_candle(&run, &path, &cfg, &rays, &audio);
    println!("short lookahead: tract vs candle max |rgb diff| {d_rgb:.2e}, segments {d_seg:.2e}");
    assert!(d_rgb <= TOL && d_seg <= TOL, "{d_rgb} {d_seg}");
    let (want, _) = candle_render(&run, &rays, &audio);
    let shape = [a.att_frames, a.window, a.n_features];
    let per_window = a.window * a.n_features;
    let centre = a.att_frames / 2;
    // Every value it must not read, changed.
    let mut unread = audio.clone();
    for (i, v) in unread.iter_mut().enumerate() {
        let (w, row) = (i / per_window, (i % per_window) / a.n_features);
        if w != centre || row >= rows {
            *v = 3.0 - *v;
        }
    }
    let (rgb_unread, _) = tract_render(&path, &rays, &unread, shape);
    let (candle_unread, _) = candle_render(&run, &rays, &unread);
    assert_eq!(
        max_diff(&rgb, &rgb_unread),
        0.0,
        "the graph reads a later row"
    );
    assert_eq!(
        max_diff(&want, &candle_unread),
        0.0,
        "candle reads a later row"
    );
    // The last row it reads does reach the colours.
    let mut read = audio.clone();
    let last = centre * per_window + (rows - 1) * a.n_features;
    for v in &mut read[last..last + a.n_features] {
        *v = 3.0 - *v;
    }
    let (rgb_read, _) = tract_render(&path, &rays, &read, shape);
    assert!(
        max_diff(&rgb, &rgb_read) > 1e-5,
        "row {} is not read",
        rows - 1
    );
    // With attention the neighbours' windows would be read too: refused.
    let mut bad = cfg.clone();
    bad.attention = true;
    let err = bad.check().unwrap_err().to_string();
    assert!(
        err.contains("`model.audio.ahead` needs `model.attention` off"),
        "{err}"
    );
}
