//! The bad-input suite: the `nldf` binary given wrong files and wrong flags. Every case must
//! end with exactly one line `error: ...` that names the file or the flag at fault, a
//! non-zero exit that is not a panic's, and no output left behind.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

use nldf_core::audio::{FeatureConfig, FeatureSource, Waveform, write_wav};
use nldf_core::dataset::AUDIO_SOURCE_FILE;

mod prepare;
mod prepare_roll;
mod synth_video;

/// Runs `nldf` with `args`.
fn nldf<I, S>(args: I) -> Output
where
    I: IntoIterator<Item = S>,
    S: Into<OsString>,
{
    Command::new(env!("CARGO_BIN_EXE_nldf"))
        .args(args.into_iter().map(Into::into))
        .env_remove("ORT_DYLIB_PATH")
        .output()
        .expect("running nldf")
}

/// Runs `nldf` and asserts it succeeded.
fn nldf_ok<I, S>(args: I) -> Output
where
    I: IntoIterator<Item = S>,
    S: Into<OsString>,
{
    let out = nldf(args);
    assert!(
        out.status.success(),
        "nldf failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// A small dataset whose audio is nldf's own 5-mel features, with a trained tiny teacher
/// and student and the exported model, made once through the command line.
struct Fixture {
    _dir: tempfile::TempDir,
    data: PathBuf,
    run: PathBuf,
    model: PathBuf,
    wav: PathBuf,
}

fn fixture() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| {
        let dir = tempfile::Builder::new()
            .prefix("cli-fixture")
            .tempdir_in(env!("CARGO_TARGET_TMPDIR"))
            .unwrap();
        let data = dir.path().join("data");
        nldf_tests::write_tiny_dataset(&data);
        let source = FeatureSource::Nldf(FeatureConfig {
            n_mels: 5,
            ..FeatureConfig::default()
        });
        nldf_core::files::write_json(&data.join(AUDIO_SOURCE_FILE), &source).unwrap();
        let run = dir.path().join("run");
        let s = |p: &Path| p.to_str().unwrap().to_string();
        nldf_ok([
            "train",
            "teacher",
            "--data",
            &s(&data),
            "--run",
            &s(&run),
            "--preset",
            "tiny",
            "--iters",
            "3",
        ]);
        nldf_ok([
            "train",
            "student",
            "--data",
            &s(&data),
            "--run",
            &s(&run),
            "--depth",
            "tiny",
            "--iters",
            "2",
        ]);
        nldf_ok(["export", "--run", &s(&run)]);
        let wav = dir.path().join("speech.wav");
        write_wav(
            &wav,
            &Waveform {
                sample_rate: 16_000,
                samples: (0..8000).map(|i| (i as f32 * 0.05).sin() * 0.3).collect(),
            },
        )
        .unwrap();
        Fixture {
            model: run.join("model.onnx"),
            _dir: dir,
            data,
            run,
            wav,
        }
    })
}

/// A fresh folder for one case.
fn scratch() -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix("cli-case")
        .tempdir_in(env!("CARGO_TARGET_TMPDIR"))
        .unwrap()
}

/// The fixture's dataset copied to `dir/data`, damaged by `damage`.
fn damaged_data(dir: &Path, damage: impl FnOnce(&Path)) -> PathBuf {
    let data = dir.join("data");
    nldf_tests::copy_dir(&fixture().data, &data);
    damage(&data);
    data
}

/// The fixture's run copied to `dir/run`, damaged by `damage`.
fn damaged_run(dir: &Path, damage: impl FnOnce(&Path)) -> PathBuf {
    let run = dir.join("run");
    nldf_tests::copy_dir(&fixture().run, &run);
    damage(&run);
    run
}

/// Cuts the file at `path` to its first half.
fn cut_in_half(path: &Path) {
    let b = std::fs::read(path).unwrap();
    std::fs::write(path, &b[..b.len() / 2]).unwrap();
}

fn edit_json(path: &Path, edit: impl FnOnce(&mut serde_json::Value)) {
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    edit(&mut v);
    std::fs::write(path, v.to_string()).unwrap();
}

/// Cases run and refused, counted for the report.
static CASES: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// Runs `nldf args` and asserts the refusal: one `error:` line, the last on stderr, naming
/// every needle; a non-zero exit that is not a panic's (101); and none of `absent` left.
#[track_caller]
fn refused(case: &str, args: &[String], needles: &[&str], absent: &[&Path]) {
    let out = nldf(args);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let code = out.status.code();
    assert!(
        !out.status.success() && code != Some(101),
        "{case}: exit {code:?}\n{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{case}: panic\n{stderr}");
    let lines: Vec<&str> = stderr.lines().filter(|l| !l.trim().is_empty()).collect();
    let errors: Vec<&&str> = lines.iter().filter(|l| l.starts_with("error")).collect();
    assert_eq!(errors.len(), 1, "{case}: want one error line\n{stderr}");
    let last = lines.last().copied().unwrap_or_default();
    assert!(
        last.starts_with("error: "),
        "{case}: last line {last:?}\n{stderr}"
    );
    for needle in needles {
        assert!(
            last.contains(needle),
            "{case}: {last:?} does not name {needle:?}"
        );
    }
    for path in absent {
        assert!(!path.exists(), "{case}: left {} behind", path.display());
    }
    CASES.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    println!("{case}: {last}");
}

fn s(p: &Path) -> String {
    p.to_str().unwrap().to_string()
}

fn args(list: &[&str]) -> Vec<String> {
    list.iter().map(|a| a.to_string()).collect()
}

/// A damage done to a copy of a folder: what it is, the damage, and the name its error must
/// give.
type Damage = (&'static str, Box<dyn Fn(&Path)>, &'static str);

/// A misuse of the command line: what it is, the arguments, the names its error must give
/// and the paths that must not exist after it.
type Misuse<'a> = (&'a str, Vec<String>, Vec<&'a str>, Vec<PathBuf>);

/// Each case's damage done to a copy of the fixture's dataset, which `nldf train teacher`
/// must then refuse, naming the needle and writing no run.
fn refuse_damaged_datasets(cases: Vec<Damage>) {
    for (case, damage, needle) in cases {
        let dir = scratch();
        let data = damaged_data(dir.path(), damage);
        let (a, run) = train_teacher(&data, dir.path());
        refused(case, &a, &[needle], &[&run]);
    }
}

/// `nldf train teacher` on the dataset `data` into `dir/run`.
fn train_teacher(data: &Path, dir: &Path) -> (Vec<String>, PathBuf) {
    let run = dir.join("run");
    let a = args(&[
        "train",
        "teacher",
        "--data",
        &s(data),
        "--run",
        &s(&run),
        "--preset",
        "tiny",
        "--iters",
        "2",
    ]);
    (a, run)
}

#[test]
fn bad_transforms_files_are_refused() {
    let cases: Vec<Damage> = vec![
        (
            "transforms_train.json missing",
            Box::new(|d: &Path| std::fs::remove_file(d.join("transforms_train.json")).unwrap()),
            "transforms_train.json",
        ),
        (
            "transforms_train.json not JSON",
            Box::new(|d: &Path| std::fs::write(d.join("transforms_train.json"), "{ nope").unwrap()),
            "transforms_train.json",
        ),
        (
            "transforms_val.json cut short",
            Box::new(|d: &Path| cut_in_half(&d.join("transforms_val.json"))),
            "transforms_val.json",
        ),
        (
            "a matrix that is not rigid",
            Box::new(|d: &Path| {
                edit_json(&d.join("transforms_train.json"), |v| {
                    v["frames"][1]["transform_matrix"][0][0] = 3.0.into()
                })
            }),
            "transforms_train.json",
        ),
        (
            "aud_id beyond aud.npy",
            Box::new(|d: &Path| {
                edit_json(&d.join("transforms_train.json"), |v| {
                    v["frames"][0]["aud_id"] = 99.into()
                })
            }),
            "aud_id 99",
        ),
        (
            "negative focal length",
            Box::new(|d: &Path| {
                edit_json(&d.join("transforms_train.json"), |v| {
                    v["focal_len"] = (-5.0).into()
                })
            }),
            "focal_len",
        ),
        (
            "face_rect outside the image",
            Box::new(|d: &Path| {
                edit_json(&d.join("transforms_train.json"), |v| {
                    v["frames"][0]["face_rect"] = serde_json::json!([500, 500, 10, 10])
                })
            }),
            "face_rect",
        ),
        (
            "near without far",
            Box::new(|d: &Path| {
                edit_json(&d.join("transforms_train.json"), |v| {
                    v.as_object_mut().unwrap().remove("far");
                })
            }),
            "near",
        ),
        (
            "no training frames",
            Box::new(|d: &Path| {
                edit_json(&d.join("transforms_train.json"), |v| {
                    v["frames"] = serde_json::json!([])
                })
            }),
            "has no frames",
        ),
        (
            "frames as a string",
            Box::new(|d: &Path| {
                edit_json(&d.join("transforms_train.json"), |v| {
                    v["frames"] = "many".into()
                })
            }),
            "transforms_train.json",
        ),
        (
            "a scene.json whose head bounds are not two corners",
            Box::new(|d: &Path| {
                std::fs::write(d.join("scene.json"), r#"{"head_bounds": "big"}"#).unwrap()
            }),
            "scene.json",
        ),
        (
            "a huge face_rect",
            Box::new(|d: &Path| {
                edit_json(&d.join("transforms_train.json"), |v| {
                    v["frames"][0]["face_rect"] =
                        serde_json::json!([i64::MAX, i64::MAX, i64::MAX, i64::MAX])
                })
            }),
            "face_rect",
        ),
    ];
    refuse_damaged_datasets(cases);
}

#[test]
fn bad_images_and_audio_files_are_refused() {
    let cases: Vec<Damage> = vec![
        (
            "a frame that is not a PNG",
            Box::new(|d: &Path| std::fs::write(d.join("head_imgs/2.png"), b"not a png").unwrap()),
            "2.png",
        ),
        (
            "a frame of the wrong size",
            Box::new(|d: &Path| {
                nldf_tests::pattern_image(8, 8, 1)
                    .save_png(&d.join("head_imgs/1.png"))
                    .unwrap()
            }),
            "1.png",
        ),
        (
            "a missing frame",
            Box::new(|d: &Path| std::fs::remove_file(d.join("head_imgs/3.png")).unwrap()),
            "3.png",
        ),
        (
            "no background",
            Box::new(|d: &Path| std::fs::remove_file(d.join("bc.png")).unwrap()),
            "bc.png",
        ),
        (
            "a background cut short",
            Box::new(|d: &Path| cut_in_half(&d.join("bc.png"))),
            "bc.png",
        ),
        (
            "aud.npy of garbage",
            Box::new(|d: &Path| std::fs::write(d.join("aud.npy"), b"\x93NUMPY garbage").unwrap()),
            "aud.npy",
        ),
        (
            "aud.npy cut short",
            Box::new(|d: &Path| {
                let p = d.join("aud.npy");
                let b = std::fs::read(&p).unwrap();
                std::fs::write(&p, &b[..b.len() - 40]).unwrap();
            }),
            "aud.npy",
        ),
        (
            "aud.npy of the wrong shape",
            Box::new(|d: &Path| {
                let w = nldf_core::audio::AudioWindows {
                    n_frames: 6,
                    window: 8,
                    n_features: 5,
                    data: vec![0.0; 6 * 8 * 5],
                };
                nldf_core::dataset::save_audio_npy(&d.join("aud.npy"), &w).unwrap();
            }),
            "aud.npy",
        ),
        (
            "aud.npy holding a NaN",
            Box::new(|d: &Path| {
                let mut w = nldf_core::dataset::load_audio_npy(&d.join("aud.npy")).unwrap();
                w.data[17] = f32::NAN;
                nldf_core::dataset::save_audio_npy(&d.join("aud.npy"), &w).unwrap();
            }),
            "aud.npy",
        ),
        (
            "aud.json not JSON",
            Box::new(|d: &Path| std::fs::write(d.join("aud.json"), "[").unwrap()),
            "aud.json",
        ),
        (
            "aud.json describing other windows",
            Box::new(|d: &Path| {
                let src = FeatureSource::Nldf(FeatureConfig::default());
                nldf_core::files::write_json(&d.join("aud.json"), &src).unwrap();
            }),
            "aud.json",
        ),
        (
            "aud.wav that is not a WAV (aud.npy another front end's)",
            Box::new(|d: &Path| {
                std::fs::remove_file(d.join("aud.json")).unwrap();
                std::fs::write(d.join("aud.wav"), b"RIFF....WAVEjunk").unwrap();
            }),
            "aud.wav",
        ),
        (
            "a parsing mask missing",
            Box::new(|d: &Path| {
                std::fs::create_dir_all(d.join("parsing")).unwrap();
            }),
            "parsing",
        ),
        (
            "landmarks for one frame only",
            Box::new(|d: &Path| {
                std::fs::create_dir_all(d.join("ori_imgs")).unwrap();
                std::fs::write(d.join("ori_imgs/0.lms"), "1 1\n".repeat(68)).unwrap();
            }),
            "1.lms are missing",
        ),
        (
            "a damaged landmarks file (the mouth read from landmarks)",
            Box::new(|d: &Path| {
                use nldf_core::region::Region;
                std::fs::create_dir_all(d.join("ori_imgs")).unwrap();
                std::fs::create_dir_all(d.join("parsing")).unwrap();
                for entry in std::fs::read_dir(d.join("head_imgs")).unwrap() {
                    let stem = entry.unwrap().path().file_stem().unwrap().to_owned();
                    let lms = d.join("ori_imgs").join(&stem).with_extension("lms");
                    std::fs::write(lms, "1 1\n".repeat(68)).unwrap();
                    let parsing = d.join("parsing").join(&stem).with_extension("png");
                    let head = vec![Region::Face; 16 * 12];
                    nldf_core::dataset::save_regions_png(
                        &parsing,
                        16,
                        12,
                        &head,
                        Region::parsing_color,
                    )
                    .unwrap();
                }
                std::fs::write(d.join("ori_imgs/2.lms"), "1 1\n".repeat(67) + "1 x\n").unwrap();
            }),
            "2.lms",
        ),
    ];
    refuse_damaged_datasets(cases);
}

#[test]
fn bad_checkpoints_and_configs_are_refused() {
    let f = fixture();
    // Checkpoints.
    let cases: Vec<Damage> = vec![
        (
            "student weights of garbage",
            Box::new(|r: &Path| {
                std::fs::write(r.join("student/model.safetensors"), b"xx").unwrap()
            }),
            "model.safetensors",
        ),
        (
            "student weights cut short",
            Box::new(|r: &Path| cut_in_half(&r.join("student/model.safetensors"))),
            "model.safetensors",
        ),
        (
            "a header that claims 2^60 bytes",
            Box::new(|r: &Path| {
                let p = r.join("student/model.safetensors");
                let mut b = std::fs::read(&p).unwrap();
                b[..8].copy_from_slice(&(1u64 << 60).to_le_bytes());
                std::fs::write(&p, b).unwrap();
            }),
            "model.safetensors",
        ),
        (
            "a student config that is not one",
            Box::new(|r: &Path| std::fs::write(r.join("student/config.json"), "{}").unwrap()),
            "config.json",
        ),
        (
            "render.json with far below near",
            Box::new(|r: &Path| {
                edit_json(&r.join("student/render.json"), |v| v["far"] = 0.1.into())
            }),
            "render.json",
        ),
    ];
    for (case, damage, needle) in cases {
        let dir = scratch();
        let run = damaged_run(dir.path(), damage);
        let out = dir.path().join("out.onnx");
        refused(
            case,
            &args(&["export", "--run", &s(&run), "--out", &s(&out)]),
            &[needle],
            &[&out],
        );
    }
    // A teacher whose weights lack a tensor: eval names the file.
    let dir = scratch();
    let run = damaged_run(dir.path(), |r| {
        let p = r.join("teacher/model.safetensors");
        let (mut t, meta) = nldf_train::trainers::checkpoint::load_tensors(&p).unwrap();
        let first = t.keys().min().unwrap().clone();
        t.remove(&first);
        nldf_train::trainers::checkpoint::save_tensors(&p, &t, meta).unwrap();
    });
    let out = dir.path().join("eval");
    refused(
        "teacher weights lacking a tensor",
        &args(&[
            "eval",
            "--run",
            &s(&run),
            "--data",
            &s(&f.data),
            "--out",
            &s(&out),
        ]),
        &["model.safetensors", "lacks weight"],
        &[&out],
    );
    // Config files.
    let configs = [
        (
            "a config with unknown keys",
            r#"{"width": -1, "depth": "many"}"#,
            "unknown field `width`",
        ),
        (
            "a config with a value out of range",
            r#"{"model": {"width": 0}}"#,
            "`model.width`",
        ),
        (
            "a config with a value of the wrong type",
            r#"{"model": {"depth": "many"}}"#,
            "`model.depth`",
        ),
        ("a config that is not JSON", "model: 3", "cfg.json"),
        ("a config naming a missing file", "", "missing.json"),
    ];
    for (case, text, needle) in configs {
        let dir = scratch();
        let cfg = if text.is_empty() {
            dir.path().join("missing.json")
        } else {
            let p = dir.path().join("cfg.json");
            std::fs::write(&p, text).unwrap();
            p
        };
        let run = dir.path().join("run");
        refused(
            case,
            &args(&[
                "train",
                "teacher",
                "--data",
                &s(&f.data),
                "--run",
                &s(&run),
                "--config",
                &s(&cfg),
            ]),
            &[needle],
            &[&run],
        );
    }
    let dir = scratch();
    let cfg = dir.path().join("student.json");
    std::fs::write(&cfg, r#"{"train": {"lamda": 0.2}}"#).unwrap();
    let run = damaged_run(dir.path(), |r| {
        std::fs::remove_dir_all(r.join("student")).unwrap()
    });
    refused(
        "a student config with a misspelt key",
        &args(&[
            "train",
            "student",
            "--data",
            &s(&f.data),
            "--run",
            &s(&run),
            "--config",
            &s(&cfg),
        ]),
        &["student.json", "unknown field `lamda`"],
        &[&run.join("student")],
    );
}

#[test]
fn bad_models_and_audio_for_render_are_refused() {
    let f = fixture();
    let model_bytes = std::fs::read(&f.model).unwrap();
    let write = |dir: &Path, name: &str, bytes: &[u8]| -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    };
    let render = |model: &Path, wav: &Path, out: &Path| {
        args(&[
            "render",
            "--model",
            &s(model),
            "--audio",
            &s(wav),
            "--out",
            &s(out),
        ])
    };
    let dir = scratch();
    let d = dir.path();
    let out = d.join("video");
    let mut flipped = model_bytes.clone();
    let at = flipped.len() / 2;
    flipped[at] ^= 0x40;
    let models = [
        (
            "a model of garbage",
            write(d, "garbage.onnx", b"\x08\x09garbage"),
            "garbage.onnx",
        ),
        ("an empty model", write(d, "empty.onnx", b""), "empty.onnx"),
        (
            "a model cut short",
            write(d, "cut.onnx", &model_bytes[..model_bytes.len() / 2]),
            "cut.onnx",
        ),
        (
            "a model with a flipped weight byte",
            write(d, "flipped.onnx", &flipped),
            "flipped.onnx",
        ),
        ("a missing model", d.join("absent.onnx"), "absent.onnx"),
        (
            "an ONNX model nldf did not write",
            {
                use prost::Message;
                let proto = nldf_model::onnx::ModelProto {
                    ir_version: Some(8),
                    graph: Some(Default::default()),
                    ..Default::default()
                };
                write(d, "foreign.onnx", &proto.encode_to_vec())
            },
            "foreign.onnx",
        ),
        (
            "a frame graph where nldf renders from the ray graph",
            {
                let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/demo");
                let bytes = std::fs::read(shipped.join("frame.onnx")).unwrap();
                write(d, "frame.onnx", &bytes)
            },
            "frame graph",
        ),
    ];
    for (case, model, needle) in models {
        refused(case, &render(&model, &f.wav, &out), &[needle], &[&out]);
    }
    let wavs = [
        (
            "a WAV of garbage",
            write(d, "garbage.wav", b"RIFF\x10\0\0\0WAVEfmt "),
            "garbage.wav",
        ),
        ("an empty WAV", write(d, "empty.wav", b""), "empty.wav"),
        ("a missing WAV", d.join("absent.wav"), "absent.wav"),
        (
            "a WAV shorter than a frame",
            {
                let p = d.join("short.wav");
                write_wav(
                    &p,
                    &Waveform {
                        sample_rate: 16_000,
                        samples: vec![0.1; 100],
                    },
                )
                .unwrap();
                p
            },
            "short.wav",
        ),
        (
            "a WAV cut inside its samples",
            {
                let b = std::fs::read(&f.wav).unwrap();
                write(d, "cut.wav", &b[..b.len() - 1])
            },
            "cut.wav",
        ),
    ];
    for (case, wav, needle) in wavs {
        refused(case, &render(&f.model, &wav, &out), &[needle], &[&out]);
    }
    let wide = d.join("wide.npy");
    let w = nldf_core::audio::AudioWindows {
        n_frames: 3,
        window: 16,
        n_features: 29,
        data: vec![0.0; 3 * 16 * 29],
    };
    nldf_core::dataset::save_audio_npy(&wide, &w).unwrap();
    refused(
        "features of another width",
        &args(&[
            "render",
            "--model",
            &s(&f.model),
            "--features",
            &s(&wide),
            "--out",
            &s(&out),
        ]),
        &["wide.npy"],
        &[&out],
    );
}

#[test]
fn command_line_misuse_is_refused() {
    let f = fixture();
    let dir = scratch();
    let d = dir.path();
    let out = d.join("out");
    let model = s(&f.model);
    let wav = s(&f.wav);
    let o = s(&out);
    let file = d.join("a_file");
    std::fs::write(&file, b"x").unwrap();
    let under_file = s(&file.join("sub"));
    let busy = d.join("busy");
    std::fs::create_dir_all(&busy).unwrap();
    std::fs::write(busy.join("keep.txt"), b"x").unwrap();
    // `nldf render` of the fixture into `out`, with `extra` flags.
    let render = |extra: &[&str]| {
        let mut a = args(&["render", "--model", &model, "--audio", &wav, "--out", &o]);
        a.extend(args(extra));
        a
    };
    let cases: Vec<Misuse> = vec![
        (
            "an unknown backend",
            render(&["--backend", "cuda"]),
            vec!["--backend", "cuda"],
            vec![out.clone()],
        ),
        (
            "an unknown subcommand",
            args(&["trian"]),
            vec!["trian"],
            vec![],
        ),
        (
            "nldf train with neither a stage nor --data and --run",
            args(&["train"]),
            vec!["--data DIR --run RUN"],
            vec![],
        ),
        (
            "nldf train on a dataset folder that is not there",
            args(&["train", "--data", &s(&d.join("nowhere")), "--run", &o]),
            vec!["nowhere", "no such dataset folder"],
            vec![out.clone()],
        ),
        (
            "nldf train with a zero wall-clock cap",
            args(&[
                "train",
                "--data",
                &s(&f.data),
                "--run",
                &o,
                "--minutes",
                "0",
            ]),
            vec!["cap must be a finite number of minutes above 0"],
            vec![out.clone()],
        ),
        (
            "an unknown flag",
            args(&["export", "--run", &s(&f.run), "--int4"]),
            vec!["--int4"],
            vec![],
        ),
        (
            "image size zero",
            render(&["--size", "0"]),
            vec!["--size"],
            vec![out.clone()],
        ),
        (
            "a negative size",
            render(&["--size=-4"]),
            vec!["--size"],
            vec![out.clone()],
        ),
        (
            "batch zero",
            render(&["--batch", "0"]),
            vec!["--batch"],
            vec![out.clone()],
        ),
        (
            "zero threads",
            render(&["--threads", "0"]),
            vec!["--threads"],
            vec![out.clone()],
        ),
        (
            "render output under a file",
            args(&[
                "render",
                "--model",
                &model,
                "--audio",
                &wav,
                "--out",
                &under_file,
            ]),
            vec!["a_file"],
            vec![],
        ),
        (
            "render into a folder that holds files",
            args(&[
                "render",
                "--model",
                &model,
                "--audio",
                &wav,
                "--out",
                &s(&busy),
            ]),
            vec!["busy"],
            vec![],
        ),
        (
            "synth output under a file",
            args(&[
                "synth",
                "--out",
                &under_file,
                "--size",
                "16",
                "--seconds",
                "1",
            ]),
            vec!["a_file"],
            vec![],
        ),
        (
            "synth of size zero",
            args(&["synth", "--out", &o, "--size", "0"]),
            vec!["size"],
            vec![out.clone()],
        ),
        (
            "synth of negative length",
            args(&["synth", "--out", &o, "--seconds=-1"]),
            vec!["seconds"],
            vec![out.clone()],
        ),
        (
            "a student without a teacher",
            args(&["train", "student", "--data", &s(&f.data), "--run", &o]),
            vec!["teacher"],
            vec![out.join("student")],
        ),
        (
            "--resume with no run",
            args(&[
                "train",
                "teacher",
                "--data",
                &s(&f.data),
                "--run",
                &o,
                "--resume",
            ]),
            vec!["resume", "out"],
            vec![out.join("teacher")],
        ),
        (
            "a teacher over a trained one without --resume",
            args(&[
                "train",
                "teacher",
                "--data",
                &s(&f.data),
                "--run",
                &s(&f.run),
            ]),
            vec!["--resume"],
            vec![],
        ),
        (
            "eval of a run that does not exist",
            args(&["eval", "--run", &o, "--data", &s(&f.data)]),
            vec!["out"],
            vec![out.clone()],
        ),
        (
            "export of a run without a student",
            args(&["export", "--run", &s(d)]),
            vec!["student"],
            vec![d.join("model.onnx")],
        ),
        (
            "synth turning the novel split less than the recorded range",
            args(&["synth", "--out", &o, "--novel-turn", "0.5"]),
            vec!["--novel-turn"],
            vec![out.clone()],
        ),
        (
            "a posed ablation with no student minutes",
            args(&[
                "ablate",
                "--data",
                &s(&f.data),
                "--run",
                &o,
                "--posed-minutes",
                "0",
            ]),
            vec!["minutes"],
            vec![out.clone()],
        ),
        (
            "a demo with negative minutes",
            args(&["demo", "--out", &o, "--minutes=-1"]),
            vec!["--minutes"],
            vec![out.clone()],
        ),
        (
            "a demo scene of 8 pixels",
            args(&["demo", "--out", &o, "--size", "8"]),
            vec!["--size", "8"],
            vec![out.clone()],
        ),
        (
            "features to a file that is not .npy",
            args(&["features", "--audio", &wav, "--out", &s(&d.join("aud.txt"))]),
            vec!["--out"],
            vec![d.join("aud.txt")],
        ),
        (
            "features of a missing WAV",
            args(&[
                "features",
                "--audio",
                &s(&d.join("none.wav")),
                "--out",
                &s(&d.join("a.npy")),
            ]),
            vec!["none.wav"],
            vec![d.join("a.npy")],
        ),
        (
            "render with neither audio nor features",
            args(&["render", "--model", &model, "--out", &o]),
            vec!["--audio"],
            vec![out.clone()],
        ),
        (
            "a render stream with features",
            args(&[
                "render",
                "--model",
                &model,
                "--audio",
                "-",
                "--stream",
                "--features",
                &wav,
            ]),
            vec!["--features"],
            vec![],
        ),
    ];
    for (case, a, needles, absent) in cases {
        let absent: Vec<&Path> = absent.iter().map(PathBuf::as_path).collect();
        refused(case, &a, &needles, &absent);
    }
}

/// The fixture's exported model renders from the WAV (so the refusals above are about the
/// damage alone), and the suite's size is reported.
#[test]
fn the_fixture_renders_and_the_suite_counts_its_cases() {
    let f = fixture();
    let dir = scratch();
    let out = dir.path().join("video");
    nldf_ok([
        "render",
        "--model",
        &s(&f.model),
        "--audio",
        &s(&f.wav),
        "--out",
        &s(&out),
        "--no-video",
    ]);
    assert!(out.join("frame_00000.png").is_file());
}

/// `nldf bench frontier` end to end on the fixture's tiny run with a tiny learned upsampler:
/// every point of its JSON has its fields and finite times, the upsampled ray graph is a
/// point in fp16 and int8 in both runtimes (`--upsampler`, its int8 keeping the product
/// `--int8-f32` names), the front is exactly the points nothing beats on both time and `val`
/// PSNR, and the speed-up names an export, never a variant of the teacher.
#[test]
fn bench_frontier_runs_end_to_end_on_a_tiny_run() {
    if let Err(e) = nldf_infer::ort_library::find_ort_library() {
        nldf_tests::tool_missing::<()>(format!("bench frontier needs onnxruntime: {e}"));
        return;
    }
    let f = fixture();
    let dir = scratch();
    let run = dir.path().join("run");
    nldf_tests::copy_dir(&f.run, &run);
    train_tiny_upsampler(&f.data, &run, dir.path());
    let out = dir.path().join("frontier");
    let a = args(&[
        "bench",
        "frontier",
        "--upsampler",
        "upsampler",
        "--int8-f32",
        "mlp.input.beam",
        "--run",
        &s(&run),
        "--data",
        &s(&f.data),
        "--out",
        &s(&out),
        "--frames",
        "2",
        "--one-thread-frames",
        "1",
        "--calibration-frames",
        "1",
        "--adnerf-frames",
        "0",
        "--timed-frames",
        "2",
        // The suite runs beside builds: the benchmark's load limit would refuse it.
        "--force",
    ]);
    let o = Command::new(env!("CARGO_BIN_EXE_nldf"))
        .args(&a)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "nldf bench frontier failed:\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    for file in ["frontier.json", "frontier.md", "frontier.png"] {
        assert!(out.join(file).is_file(), "{file} missing");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("frontier.json")).unwrap()).unwrap();
    assert!(json["machine"]["commit"].is_string(), "{}", json["machine"]);
    let points = json["points"].as_array().unwrap();
    // The head-region plot exists exactly when the points were scored with a head mask.
    let has_head = points.iter().any(|p| {
        p["scores"]
            .as_array()
            .is_some_and(|s| s.iter().any(|s| s["head_psnr"].is_number()))
    });
    assert_eq!(out.join("frontier_head.png").is_file(), has_head);
    // The teacher, its two variants, then every export in ort and tract.
    let exports = points.iter().filter(|p| p["file"].is_string()).count();
    assert!(
        points.len() >= 3 + 4 && exports >= 4,
        "{} points",
        points.len()
    );
    assert_eq!(points[0]["runtime"], "candle");
    let mut upsampled: Vec<(String, String)> = points
        .iter()
        .filter(|p| {
            p["file"]
                .as_str()
                .is_some_and(|f| f.contains("upsampler.rays."))
        })
        .map(|p| {
            let field = |k: &str| p[k].as_str().unwrap_or_default().to_string();
            (field("precision"), field("runtime"))
        })
        .collect();
    upsampled.sort();
    let want: Vec<(String, String)> = [
        ("fp16", "ort"),
        ("fp16", "tract"),
        ("int8", "ort"),
        ("int8", "tract"),
    ]
    .iter()
    .map(|(p, r)| (p.to_string(), r.to_string()))
    .collect();
    assert_eq!(upsampled, want, "the upsampled ray graph's points");
    assert_eq!(json["settings"]["upsamplers"][0], "upsampler");
    assert_eq!(json["settings"]["int8_f32"][0], "mlp.input.beam");
    let key = |p: &serde_json::Value| {
        let val = p["scores"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["split"] == "val")
            .unwrap();
        (
            p["ms_2_threads"].as_f64().unwrap(),
            val["psnr"].as_f64().unwrap(),
        )
    };
    for p in points {
        for field in ["model", "precision", "runtime"] {
            assert!(p[field].as_str().is_some_and(|v| !v.is_empty()), "{p}");
        }
        let (ms, psnr) = key(p);
        assert!(ms.is_finite() && ms > 0.0 && psnr.is_finite(), "{p}");
        assert!(p["ms_back_to_back"].as_f64().unwrap() > 0.0, "{p}");
        assert!(!p["model"].as_str().unwrap().contains("candle"), "{p}");
    }
    for (i, p) in points.iter().enumerate() {
        let (t, q) = key(p);
        let beaten = points.iter().enumerate().any(|(j, o)| {
            let (t2, q2) = key(o);
            j != i && t2 <= t && q2 >= q && (t2 < t || q2 > q)
        });
        assert_eq!(p["on_front"].as_bool(), Some(!beaten), "{p}");
    }
    for s in json["speed_up"].as_array().unwrap() {
        if let Some(name) = s["point"].as_str() {
            assert!(name.ends_with(" ort") || name.ends_with(" tract"), "{name}");
            // Two frames are two pairs: too few to show a difference, however fast.
            let r = &s["speed_up"];
            assert!(r["pairs"].as_u64().is_some_and(|n| n <= 2), "{s}");
            assert_eq!(r["verdict"], "no_difference", "{s}");
        }
    }
    let machine = &json["machine"];
    assert!(machine["load_average_1m_after"].is_number(), "{machine}");
}

/// The files of `from`'s teacher and student folders copied into `to`.
fn copy_trained_run(from: &Path, to: &Path) {
    for sub in ["teacher", "student"] {
        std::fs::create_dir_all(to.join(sub)).unwrap();
        for entry in std::fs::read_dir(from.join(sub)).unwrap() {
            let path = entry.unwrap().path();
            if path.is_file() {
                std::fs::copy(&path, to.join(sub).join(path.file_name().unwrap())).unwrap();
            }
        }
    }
}

/// A tiny upsampler's configuration, naming `student` when given.
fn upsampler_config(student: Option<&str>) -> String {
    let student = student.map_or(String::new(), |s| format!(r#""student": "{s}","#));
    format!(
        r#"{{"model": {{"factor": 2, "channels": [8, 8], "margin": 1}}, {student}
            "train": {{"iters": 6, "batch": 2, "crop": 4, "halo": 1, "pseudo_views": 2}}}}"#
    )
}

/// `nldf train upsampler` of the tiny configuration ([`upsampler_config`], written into
/// `scratch`) over `run`'s student, into `run/upsampler`.
fn train_tiny_upsampler(data: &Path, run: &Path, scratch: &Path) {
    let config = scratch.join("upsampler.json");
    std::fs::write(&config, upsampler_config(None)).unwrap();
    nldf_ok(args(&[
        "train",
        "upsampler",
        "--data",
        &s(data),
        "--run",
        &s(run),
        "--config",
        &s(&config),
    ]));
}

/// `nldf train upsampler --student NAME` with a `--config` that names another student: the
/// flag wins and says so on stderr. A configuration naming a folder that does not exist
/// trains over `--student student`, and the upsampler's saved configuration names
/// `student`; `--student` naming a folder that does not exist is refused by that name,
/// though the configuration names the trained student.
#[test]
fn train_upsampler_student_flag_overrides_the_configuration() {
    let f = fixture();
    let dir = scratch();
    let d = dir.path();
    let run = d.join("run");
    copy_trained_run(&f.run, &run);
    let config = |student: &str| {
        let path = d.join(format!("upsampler_{student}.json"));
        std::fs::write(&path, upsampler_config(Some(student))).unwrap();
        s(&path)
    };
    let train = |config: &str, student: &str, name: &str| {
        args(&[
            "train",
            "upsampler",
            "--data",
            &s(&f.data),
            "--run",
            &s(&run),
            "--config",
            config,
            "--student",
            student,
            "--name",
            name,
            "--iters",
            "2",
        ])
    };
    let elsewhere = config("elsewhere");
    let out = nldf_ok(train(&elsewhere, "student", "upsampler"));
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(
        said.contains("--student student overrides the student `elsewhere`")
            && said.contains("upsampler_elsewhere.json"),
        "the override is not said:\n{said}"
    );
    let saved: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(
            run.join("upsampler")
                .join(nldf_core::run_files::CONFIG_FILE),
        )
        .unwrap(),
    )
    .unwrap();
    assert_eq!(saved["student"], "student", "the saved configuration");

    refused(
        "--student naming a missing folder over a configuration naming the trained student",
        &train(&config("student"), "nowhere", "up2"),
        &["nowhere"],
        &[&run.join("up2")],
    );
}

/// The learned upsampler through the command line on a copy of the fixture's run: `nldf
/// train upsampler`, `nldf export --upsampler` (the ray graph, without --frame), `nldf render`
/// of a WAV with it (every frame written, the size of the model's), also with
/// `--skip-still`.
#[test]
fn an_upsampled_ray_graph_renders_from_the_command_line() {
    let f = fixture();
    let dir = scratch();
    let d = dir.path();
    let run = d.join("run");
    copy_trained_run(&f.run, &run);
    train_tiny_upsampler(&f.data, &run, d);
    let model = d.join("up.onnx");
    let out = nldf_ok(args(&[
        "export",
        "--run",
        &s(&run),
        "--upsampler",
        "upsampler",
        "--out",
        &s(&model),
    ]));
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(said.contains("learned upsampler x2"), "{said}");
    let video = d.join("video");
    nldf_ok(args(&[
        "render",
        "--model",
        &s(&model),
        "--audio",
        &s(&f.wav),
        "--out",
        &s(&video),
        "--no-video",
    ]));
    let frame = nldf_core::image::ImageRgb::load(&video.join("frame_00000.png")).unwrap();
    assert_eq!((frame.width, frame.height), (16, 12));
    // Skipping still pixels re-renders the part of the box the audio moves.
    let skipping = d.join("skipping");
    let out = nldf_ok(args(&[
        "render",
        "--model",
        &s(&model),
        "--audio",
        &s(&f.wav),
        "--out",
        &s(&skipping),
        "--no-video",
        "--skip-still",
    ]));
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(said.contains("skipping still pixels"), "{said}");
    let frames = |dir: &Path| {
        std::fs::read_dir(dir)
            .unwrap()
            .filter(|e| e.as_ref().unwrap().path().extension() == Some("png".as_ref()))
            .count()
    };
    assert_eq!(frames(&skipping), frames(&video));
    assert!(frames(&video) >= 10);
}

/// `nldf train --data DIR --run RUN` runs the demo's recipe on a dataset it did not make:
/// teacher, distilled student, export, the scores of the splits the dataset has (`val`), and
/// a video, ending with the table; the dataset itself is left as it was.
#[test]
fn nldf_train_runs_the_recipe_on_a_dataset() {
    let f = fixture();
    let dir = scratch();
    let run = dir.path().join("run");
    let digest = |root: &Path| -> Vec<(PathBuf, Vec<u8>)> {
        let mut files = Vec::new();
        let mut stack = vec![root.to_path_buf()];
        while let Some(p) = stack.pop() {
            if p.is_dir() {
                stack.extend(std::fs::read_dir(&p).unwrap().map(|e| e.unwrap().path()));
            } else {
                files.push((p.clone(), std::fs::read(&p).unwrap()));
            }
        }
        files.sort();
        files
    };
    let before = digest(&f.data);
    let out = nldf_ok(args(&[
        "train",
        "--data",
        &s(&f.data),
        "--run",
        &s(&run),
        "--teacher-iters",
        "3",
        "--student-iters",
        "3",
    ]));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("== nldf train: done"), "{stdout}");
    assert!(stdout.contains("distilled with pseudo views"), "{stdout}");
    for file in [
        "model.onnx",
        "eval/val/metrics.json",
        "teacher/model.safetensors",
    ] {
        assert!(run.join(file).is_file(), "{file} missing\n{stdout}");
    }
    // Only the splits the dataset has: the fixture has no `novel` or `voice`.
    assert!(!run.join("eval/novel").exists());
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("eval/val/metrics.json")).unwrap())
            .unwrap();
    let labels: Vec<&str> = metrics["models"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m["label"].as_str().unwrap())
        .collect();
    assert_eq!(labels, vec!["teacher", "student"]);
    assert!(digest(&f.data) == before, "the dataset changed");
}
