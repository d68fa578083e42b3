//! Inference (nldf-infer): frames rendered by the tract and onnxruntime backends agree with
//! each other and with the candle student (PSNR >= 60 dB between any two), a WAV becomes
//! PNG frames through the staging folder, and every bad input gets a one-line error with
//! nothing written.

use std::path::{Path, PathBuf};
use std::time::Duration;

use crate::util::{
    Run, candle_frame, configs, foreign_model, ort_available, random_audio, venv_ffmpeg, write_run,
    write_test_wav,
};
use glam::Mat4;
use nldf_core::audio::neighbourhood;
use nldf_core::audio::{Waveform, n_video_frames, write_wav};
use nldf_core::image::ImageRgb;
use nldf_core::metrics::psnr;
use nldf_export::WeightType;
use nldf_infer::audio::windows_from_wav;
use nldf_infer::backend::{BackendKind, BackendOptions, backend_for};
use nldf_infer::frame::{FrameRenderer, background_at};
use nldf_infer::ort_library::find_ort_library_in;
use nldf_infer::poses::{default_track, pose_at};
use nldf_infer::stream::{STREAM_REPORT_FILE, StreamJob, next_frame, paced_wav_stream};
use nldf_infer::video::{VideoJob, frame_file_name};
use nldf_model::read_model;
use nldf_train::networks::student::StudentConfig;

/// The parity bound between any two renderers' frames: 20 dB (10x in RMS error) under the
/// measured worst, about 140.9 dB (onnxruntime against candle and tract, the ops-only config).
const MIN_PSNR: f64 = 120.0;

#[test]
fn infer_frames_agree_across_tract_ort_and_candle() {
    let with_ort = ort_available();
    for (c, cfg) in configs().into_iter().enumerate() {
        let run = write_run(&cfg, 101 + c as u64);
        let path = run.export(WeightType::F32);
        let model = read_model(&path).unwrap();
        let info = &model.info;
        let audio = neighbourhood(&random_audio(&cfg, 12, 15), 6, cfg.audio.att_frames);
        let poses = [
            ("default pose", default_track(info, 1)[0]),
            ("track frame 40", default_track(info, 41)[40]),
        ];
        for size in [None, Some(40)] {
            let mut kinds = vec![BackendKind::Tract];
            if with_ort {
                kinds.push(BackendKind::Ort);
            }
            // Batch 256: several batches per frame and a padded last one.
            let options = BackendOptions {
                batch_size: 256,
                threads: 2,
                spin: true,
            };
            let mut renderers: Vec<(BackendKind, FrameRenderer)> = kinds
                .iter()
                .map(|&k| {
                    let backend = backend_for(&model, k, options).unwrap();
                    (k, FrameRenderer::new(backend, size).unwrap())
                })
                .collect();
            let k = renderers[0].1.intrinsics();
            let background = background_at(info, k.width, k.height).unwrap();
            for (pose_name, c2w) in poses {
                let mut frames = vec![(
                    "candle".to_string(),
                    candle_frame(&run, k, c2w, &audio, &background),
                )];
                for (kind, renderer) in &mut renderers {
                    let frame = renderer.render(c2w, &audio).unwrap();
                    assert!(
                        frame.head_pixels > 0 && frame.head_pixels < k.n_pixels(),
                        "the test camera should see both head and background"
                    );
                    frames.push((kind.name().to_string(), frame.image));
                }
                for a in 0..frames.len() {
                    for b in a + 1..frames.len() {
                        let p = psnr(&frames[a].1, &frames[b].1).unwrap();
                        println!(
                            "config {c}, {}x{}, {pose_name}: {} vs {}: PSNR {p:.1} dB",
                            k.width, k.height, frames[a].0, frames[b].0
                        );
                        assert!(p >= MIN_PSNR, "{} vs {}: {p} dB", frames[a].0, frames[b].0);
                    }
                }
            }
        }
    }
}

/// A tiny exported student (seed `seed`) and a WAV of `seconds` beside it.
fn tiny_model_and_wav(seed: u64, seconds: f32) -> (Run, PathBuf, PathBuf) {
    let run = write_run(&StudentConfig::tiny(), seed);
    let path = run.export(WeightType::F32);
    let wav = run.root.join("speech.wav");
    write_test_wav(&wav, seconds);
    (run, path, wav)
}

/// Small batches on one thread: several batches per frame, quick to compile.
const TEST_OPTIONS: BackendOptions = BackendOptions {
    batch_size: 512,
    threads: 1,
    spin: true,
};

fn job(model: &Path, audio: &Path, out: &Path) -> VideoJob {
    VideoJob {
        model: model.to_path_buf(),
        audio: Some(audio.to_path_buf()),
        features: None,
        poses: None,
        out: out.to_path_buf(),
        backend: BackendKind::Tract,
        options: TEST_OPTIONS,
        size: None,
        mp4: false,
        ffmpeg: None,
        skip: None,
    }
}

#[test]
fn infer_render_video_writes_a_png_per_frame_through_staging() {
    let cfg = StudentConfig::tiny();
    let (run, path, wav) = tiny_model_and_wav(111, 0.5);
    let out = run.root.join("video");
    let plan = job(&path, &wav, &out).plan().unwrap();
    let want_frames = n_video_frames(8000, 16_000, run.spec.fps);
    assert_eq!(plan.n_frames(), want_frames);
    assert!(!out.exists(), "nothing appears before the render finishes");
    let mut seen = 0;
    let report = plan.render(|p| seen = p.done).unwrap();
    assert_eq!((seen, report.n_frames), (want_frames, want_frames));
    assert_eq!(report.out, out);
    assert_eq!(report.files.len(), want_frames);
    assert!(report.video.is_none());
    for (f, file) in report.files.iter().enumerate() {
        assert_eq!(*file, out.join(frame_file_name(f)));
        assert!(file.is_file());
    }
    assert_no_staging(&run.root);
    // Frame 3 is the candle student's frame for the WAV's audio and the default track.
    let info = read_model(&path).unwrap().info;
    let windows = windows_from_wav(&info, &path, &wav).unwrap();
    let audio = neighbourhood(&windows, 3, cfg.audio.att_frames);
    let k = info.spec.intrinsics;
    let background = background_at(&info, k.width, k.height).unwrap();
    let c2w = default_track(&info, want_frames)[3];
    let want = candle_frame(&run, k, c2w, &audio, &background).to_rgb8();
    let got = ImageRgb::load(&report.files[3]).unwrap().to_rgb8();
    let worst = want
        .iter()
        .zip(&got)
        .map(|(a, b)| a.abs_diff(*b))
        .max()
        .unwrap();
    println!("render: frame 3's PNG vs the candle frame: max 8-bit difference {worst}");
    assert!(worst <= 1, "{worst}");
    // An existing empty folder is replaced; rendering again into a full one is refused.
    let empty = run.root.join("empty");
    std::fs::create_dir(&empty).unwrap();
    job(&path, &wav, &empty)
        .plan()
        .unwrap()
        .render(|_| {})
        .unwrap();
    assert!(empty.join(frame_file_name(0)).is_file());
}

/// No staging folder is left in `dir`.
fn assert_no_staging(dir: &Path) {
    let left: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.to_string_lossy().contains(".partial-"))
        .collect();
    assert!(left.is_empty(), "staging left behind: {left:?}");
}

#[test]
fn infer_bad_inputs_get_one_line_errors_and_write_nothing() {
    let cfg = StudentConfig::tiny();
    let run = write_run(&cfg, 121);
    let model = run.export(WeightType::F32);
    let dir = run.root.join("bad");
    std::fs::create_dir_all(&dir).unwrap();
    let wav = dir.join("good.wav");
    write_test_wav(&wav, 0.3);
    let write = |name: &str, bytes: &[u8]| -> PathBuf {
        let p = dir.join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    };
    let out = dir.join("out");
    let check = |what: &str, job: VideoJob, needle: &str| {
        let Err(err) = job.plan() else {
            panic!("{what} was accepted")
        };
        let msg = err.to_string();
        println!("{what}: {msg}");
        nldf_tests::assert_one_line_naming(&msg, needle);
        assert!(
            !job.out.exists(),
            "{what}: {} was created",
            job.out.display()
        );
        let parent = job.out.parent().unwrap();
        if parent.is_dir() {
            assert_no_staging(parent);
        }
    };
    // Broken WAVs: noise, a header cut short, an empty file, a missing file.
    let good_wav = std::fs::read(&wav).unwrap();
    for (name, bytes) in [
        (
            "noise.wav",
            (0..999u32)
                .map(|i| (i * 7919 % 251) as u8)
                .collect::<Vec<u8>>(),
        ),
        ("cut.wav", good_wav[..30].to_vec()),
        ("empty.wav", vec![]),
    ] {
        let p = write(name, &bytes);
        check(name, job(&model, &p, &out), name);
    }
    check(
        "missing.wav",
        job(&model, &dir.join("missing.wav"), &out),
        "missing.wav",
    );
    // A WAV shorter than one video frame.
    let short = dir.join("short.wav");
    write_test_wav(&short, 0.01);
    check("short.wav", job(&model, &short, &out), "short.wav");
    // A model without nldf metadata, and a truncated one.
    let foreign = write("foreign.onnx", &foreign_model(vec![]));
    check("foreign.onnx", job(&foreign, &wav, &out), "foreign.onnx");
    let bytes = std::fs::read(&model).unwrap();
    let cut = write("cut.onnx", &bytes[..bytes.len() / 2]);
    check("cut.onnx", job(&cut, &wav, &out), "cut.onnx");
    // Pose files: NaN (as Python's json writes it), a scaled matrix, no frames.
    let rows = |m: [[f32; 4]; 4]| serde_json::to_string(&m).unwrap();
    let transforms = |matrices: &[String]| {
        let frames: Vec<String> = matrices
            .iter()
            .enumerate()
            .map(|(i, m)| format!(r#"{{"img_id": {i}, "aud_id": {i}, "transform_matrix": {m}}}"#))
            .collect();
        format!(
            r#"{{"focal_len": 30.0, "cx": 12.0, "cy": 9.0, "frames": [{}]}}"#,
            frames.join(", ")
        )
    };
    let pose = run.spec.default_pose;
    let nan = rows(pose)
        .replacen("1.0", "NaN", 1)
        .replacen("2.2", "NaN", 1);
    assert!(nan.contains("NaN"), "{nan}");
    let mut scaled = pose;
    scaled[0][0] *= 2.0;
    for (name, text) in [
        ("nan.json", transforms(&[rows(pose), nan])),
        ("scaled.json", transforms(&[rows(pose), rows(scaled)])),
        ("no_frames.json", transforms(&[])),
    ] {
        let p = write(name, text.as_bytes());
        let mut j = job(&model, &wav, &out);
        j.poses = Some(p);
        check(name, j, name);
    }
    // Unwritable output folders: below a file, and a folder that already holds files.
    let file = write("a_file", b"x");
    check(
        "output below a file",
        job(&model, &wav, &file.join("out")),
        "a_file",
    );
    let full = dir.join("full");
    std::fs::create_dir(&full).unwrap();
    std::fs::write(full.join("keep.txt"), b"x").unwrap();
    let Err(err) = job(&model, &wav, &full).plan() else {
        panic!("a full output folder was accepted")
    };
    nldf_tests::assert_one_line_naming(&err.to_string(), "full");
    assert_eq!(std::fs::read_dir(&full).unwrap().count(), 1);
    // A size out of range.
    let mut j = job(&model, &wav, &out);
    j.size = Some(0);
    let msg = j.plan().unwrap_err().to_string();
    assert!(msg.contains("size"), "{msg}");
}

#[test]
fn infer_missing_onnxruntime_library_says_how_to_get_it() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("libonnxruntime.so.1.31.1");
    let msg = find_ort_library_in(Some(missing.as_os_str()), &[])
        .unwrap_err()
        .to_string();
    nldf_tests::assert_one_line_naming(&msg, "libonnxruntime.so.1.31.1");
    assert!(
        msg.contains("ORT_DYLIB_PATH") && msg.contains("pip install onnxruntime"),
        "{msg}"
    );
    let msg = find_ort_library_in(None, &[dir.path().to_path_buf()])
        .unwrap_err()
        .to_string();
    nldf_tests::assert_one_line_naming(&msg, "ORT_DYLIB_PATH");
    // The wheel's layout is found.
    let capi = dir
        .path()
        .join(".venv/lib/python3.12/site-packages/onnxruntime/capi");
    std::fs::create_dir_all(&capi).unwrap();
    std::fs::write(capi.join("libonnxruntime.so.1.31.1"), b"").unwrap();
    let found = find_ort_library_in(None, &[dir.path().to_path_buf()]).unwrap();
    assert_eq!(found, capi.join("libonnxruntime.so.1.31.1"));
}

/// Without `ORT_DYLIB_PATH` or a `.venv`, the library comes from the `onnxruntime` package
/// of the `python3` on the PATH, then from the system's library path; with none of them,
/// one line says the command that fixes it.
#[test]
fn infer_onnxruntime_is_found_in_pythons_package_then_the_system_path() {
    use nldf_infer::ort_library::OrtSearch;
    let dir = tempfile::tempdir().unwrap();
    let package = dir.path().join("site-packages/onnxruntime");
    std::fs::create_dir_all(package.join("capi")).unwrap();
    std::fs::write(package.join("capi/libonnxruntime.so.1.31.1"), b"").unwrap();
    // A stand-in python3 that answers the package query as the real one does.
    let python = dir.path().join("python3");
    std::fs::write(&python, format!("#!/bin/sh\necho {}\n", package.display())).unwrap();
    let mut perms = std::fs::metadata(&python).unwrap().permissions();
    std::os::unix::fs::PermissionsExt::set_mode(&mut perms, 0o755);
    std::fs::set_permissions(&python, perms).unwrap();
    let system = dir.path().join("lib");
    std::fs::create_dir_all(&system).unwrap();
    std::fs::write(system.join("libonnxruntime.so.1.32.0"), b"").unwrap();
    let empty = dir.path().join("empty");
    std::fs::create_dir_all(&empty).unwrap();

    let search = OrtSearch {
        dylib_path: None,
        roots: vec![empty.clone()],
        python: Some(python.clone()),
        system_dirs: vec![system.clone()],
    };
    let found = search.find().unwrap();
    assert_eq!(found.path, package.join("capi/libonnxruntime.so.1.31.1"));
    assert_eq!(found.version().as_deref(), Some("1.31.1"));
    assert!(found.place.contains("python3"), "{}", found.place);

    let no_python = OrtSearch {
        python: None,
        ..search.clone()
    };
    let found = no_python.find().unwrap();
    assert_eq!(found.path, system.join("libonnxruntime.so.1.32.0"));
    assert!(found.place.contains("system"), "{}", found.place);

    let nothing = OrtSearch {
        system_dirs: vec![empty],
        ..no_python
    };
    let msg = nothing.find().unwrap_err().to_string();
    nldf_tests::assert_one_line_naming(&msg, "pip install onnxruntime");
}

#[test]
fn infer_pose_lists_play_forwards_then_backwards() {
    let poses: Vec<Mat4> = (0..3)
        .map(|i| Mat4::from_translation(glam::Vec3::X * i as f32))
        .collect();
    let order: Vec<usize> = (0..9)
        .map(|f| {
            let p = pose_at(&poses, f);
            p.w_axis.x as usize
        })
        .collect();
    assert_eq!(order, [0, 1, 2, 1, 0, 1, 2, 1, 0]);
    assert_eq!(pose_at(&poses[..1], 5), poses[0]);
}

fn stream_job(model: &Path, out: &Path, drop_behind: Option<usize>) -> StreamJob {
    StreamJob {
        model: model.to_path_buf(),
        poses: None,
        out: out.to_path_buf(),
        backend: BackendKind::Tract,
        options: TEST_OPTIONS,
        size: None,
        drop_behind,
    }
}

/// `nldf render --stream` without skipping renders exactly the frames of a file render of
/// the same audio, byte for byte, while the audio arrives in pieces faster than real time,
/// and waits only for the audio its model reads: AD-NeRF's windows and 8-frame attention
/// at 25 fps read 0.2725 s ahead, the window alone 0.1525 s, a short-lookahead student
/// reading 5 feature frames past the centre 0.0925 s.
#[test]
fn infer_stream_renders_the_file_renders_frames_as_audio_arrives() {
    let mut no_attention = StudentConfig::tiny();
    no_attention.attention = false;
    let mut short = no_attention.clone();
    short.audio.ahead = Some(5);
    for (cfg, lookahead) in [
        (StudentConfig::tiny(), 0.2725),
        (no_attention, 0.1525),
        (short, 0.0925),
    ] {
        assert_stream_renders_the_file_renders_frames(&cfg, lookahead);
    }
}

fn assert_stream_renders_the_file_renders_frames(cfg: &StudentConfig, lookahead: f64) {
    let run = write_run(cfg, 112);
    let path = run.export(WeightType::F32);
    let wav = run.root.join("speech.wav");
    write_test_wav(&wav, 0.6);
    let file_out = run.root.join("file");
    let file = job(&path, &wav, &file_out)
        .plan()
        .unwrap()
        .render(|_| {})
        .unwrap();
    let stream_out = run.root.join("stream");
    let plan = stream_job(&path, &stream_out, None).plan().unwrap();
    let wave = nldf_core::audio::read_wav(&wav).unwrap();
    // 20 ms pieces at 20x real time.
    let source = paced_wav_stream(&wave, 20.0, Duration::from_millis(20)).unwrap();
    let mut order = Vec::new();
    let report = plan
        .run(source, "test stream", |f, _| order.push(f.index))
        .unwrap();
    assert_eq!(report.n_frames, file.n_frames);
    assert_eq!(report.dropped, 0);
    assert_eq!(order, (0..file.n_frames).collect::<Vec<_>>());
    for f in 0..file.n_frames {
        let a = std::fs::read(file_out.join(frame_file_name(f))).unwrap();
        let b = std::fs::read(stream_out.join(frame_file_name(f))).unwrap();
        assert!(a == b, "frame {f} differs between the file and the stream");
    }
    println!(
        "lookahead {lookahead} s off by {:e}",
        (report.lookahead_s - lookahead).abs()
    );
    // Measured worst about 5.6e-17: f64 rounding.
    assert!(
        (report.lookahead_s - lookahead).abs() < 4e-16,
        "{} s, expected {lookahead}",
        report.lookahead_s
    );
    assert!(report.latency.max_ms >= report.latency.p50_ms && report.latency.p50_ms > 0.0);
    let saved: serde_json::Value =
        serde_json::from_slice(&std::fs::read(stream_out.join(STREAM_REPORT_FILE)).unwrap())
            .unwrap();
    assert_eq!(saved["frames"].as_array().unwrap().len(), file.n_frames);
}

#[test]
fn infer_stream_skips_to_the_newest_frame_only_beyond_its_slack() {
    assert_eq!(next_frame(3, 3, Some(0)), None);
    assert_eq!(next_frame(3, 4, Some(0)), Some((3, 0)));
    assert_eq!(next_frame(3, 9, Some(0)), Some((8, 5)));
    assert_eq!(next_frame(3, 9, None), Some((3, 0)));
    // Two frames may wait behind the next one: a third makes it skip to the newest.
    assert_eq!(next_frame(3, 6, Some(2)), Some((3, 0)));
    assert_eq!(next_frame(3, 7, Some(2)), Some((6, 3)));
    assert_eq!(next_frame(3, 4, Some(2)), Some((3, 0)));
}

#[test]
fn infer_bad_streams_get_one_line_errors() {
    let cfg = StudentConfig::tiny();
    let run = write_run(&cfg, 113);
    let path = run.export(WeightType::F32);
    let stream_job = |out: &Path| stream_job(&path, out, Some(0));
    let wave = Waveform {
        sample_rate: 16_000,
        samples: vec![0.1; 16_000],
    };
    let mut good = Vec::new();
    let tmp = run.root.join("good.wav");
    write_wav(&tmp, &wave).unwrap();
    good.extend(std::fs::read(&tmp).unwrap());
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("empty", Vec::new(), "empty stream"),
        ("not a WAV", b"ID3\x04 this is an mp3 file".to_vec(), "RIFF"),
        ("cut in the header", good[..30].to_vec(), "header"),
        (
            "too short",
            good[..44 + 2 * 100].to_vec(),
            "shorter than one video frame",
        ),
    ];
    for (what, bytes, needle) in cases {
        let out = run.root.join(format!("out_{}", what.replace(' ', "_")));
        let plan = stream_job(&out).plan().unwrap();
        let err = plan
            .run(Box::new(std::io::Cursor::new(bytes)), "stdin", |_, _| {})
            .unwrap_err()
            .to_string();
        println!("{what}: {err}");
        assert!(
            err.starts_with("stdin: ") && err.contains(needle),
            "{what}: {err}"
        );
        assert!(!err.contains('\n'));
        assert!(!out.join(STREAM_REPORT_FILE).exists());
    }
    // A full output folder is refused before anything is read.
    let full = run.root.join("full");
    std::fs::create_dir(&full).unwrap();
    std::fs::write(full.join("x"), b"x").unwrap();
    let err = stream_job(&full).plan().unwrap_err().to_string();
    assert!(err.contains("not empty"), "{err}");
}

/// With ffmpeg, `nldf render` also writes `video.mp4`: one video frame per PNG at the
/// model's fps and the WAV as its audio, as ffmpeg itself reads it back.
#[test]
fn infer_render_muxes_an_mp4_with_the_audio_when_ffmpeg_is_there() {
    let Some(ffmpeg) = venv_ffmpeg() else { return };
    let (run, path, wav) = tiny_model_and_wav(114, 1.0);
    let out = run.root.join("video");
    let report = VideoJob {
        mp4: true,
        ffmpeg: Some(ffmpeg.clone()),
        ..job(&path, &wav, &out)
    }
    .plan()
    .unwrap()
    .render(|_| {})
    .unwrap();
    let video = report
        .video
        .clone()
        .expect("an MP4 was asked for and ffmpeg given");
    assert_eq!(video, out.join("video.mp4"));
    assert!(!report.ffmpeg_missing);
    // Decode every frame; count them and read the streams ffmpeg reports.
    let probe = std::process::Command::new(&ffmpeg)
        .args(["-nostdin", "-i"])
        .arg(&video)
        .args(["-map", "0:v", "-f", "null", "-"])
        .output()
        .unwrap();
    let log = String::from_utf8_lossy(&probe.stderr);
    assert!(
        probe.status.success(),
        "ffmpeg cannot decode the video:\n{log}"
    );
    let k = read_model(&path).unwrap().info.spec.intrinsics;
    // Odd sizes are padded to even ones for yuv420p.
    let size = format!("{}x{}", k.width.div_ceil(2) * 2, k.height.div_ceil(2) * 2);
    assert!(log.contains("Video:") && log.contains(&size), "{log}");
    assert!(log.contains("Audio: aac"), "{log}");
    let frames: usize = log
        .rsplit("frame=")
        .next()
        .and_then(|t| t.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no frame count in:\n{log}"));
    println!(
        "mp4: {frames} frames of {size} with AAC audio, {} PNG frames",
        report.n_frames
    );
    assert_eq!(frames, report.n_frames);
    // A named ffmpeg that is not there is an error before anything is written.
    let err = VideoJob {
        mp4: true,
        ffmpeg: Some(run.root.join("no-ffmpeg")),
        ..job(&path, &wav, &run.root.join("video2"))
    }
    .plan()
    .unwrap_err()
    .to_string();
    assert!(err.contains("no ffmpeg binary"), "{err}");
    assert!(!run.root.join("video2").exists());
}

/// Skipping still pixels with the default 8 probes: on a still pose, on every frame whose
/// audio is a probe's, no pixel kept from the full frame differs from the full render by
/// more than the threshold (the pixels over it are re-rendered, exactly as in full); on the
/// other frames the threshold is no bound (the README gives the measured one); a full frame comes
/// every `refresh` frames; on a moving pose every frame is full and identical; and
/// `nldf render --skip-still` writes the same frames as the skipper.
#[test]
fn infer_skipping_still_pixels_stays_within_its_threshold() {
    use nldf_infer::still::{FrameKind, SkipConfig, StillSkipper, bench_track, probe_frames};
    let (run, path, wav) = tiny_model_and_wav(117, 0.6);
    let model = read_model(&path).unwrap();
    let info = model.info.clone();
    let windows = windows_from_wav(&info, &path, &wav).unwrap();
    let n = windows.n_frames;
    let att = info.audio.att_frames;
    let audio = |f: usize| neighbourhood(&windows, f, att);
    let renderer = || {
        FrameRenderer::new(
            backend_for(&model, BackendKind::Tract, TEST_OPTIONS).unwrap(),
            None,
        )
        .unwrap()
    };
    let (mut full, mut skipping) = (renderer(), renderer());
    // The threshold: the median spread of a head pixel over the clip's frames, so that
    // about half the head is re-rendered.
    let pose = default_track(&info, 1)[0];
    let head = full.rays(pose).pixels.len();
    let mut spread = vec![(f32::INFINITY, f32::NEG_INFINITY); 3 * head];
    for f in 0..n {
        let rgb = full.run_rays(&full.rays(pose), &audio(f)).unwrap().rgb;
        for (s, v) in spread.iter_mut().zip(rgb) {
            *s = (s.0.min(v), s.1.max(v));
        }
    }
    let mut widths: Vec<f32> = spread
        .chunks(3)
        .map(|p| p.iter().map(|(lo, hi)| hi - lo).fold(0.0, f32::max))
        .collect();
    widths.sort_by(f32::total_cmp);
    let config = SkipConfig {
        threshold: widths[head / 2],
        refresh: 6,
        ..SkipConfig::default()
    };
    let probed = probe_frames(n, config.probes);
    assert!(
        probed.len() < n,
        "every frame is a probe: the test would hold by construction"
    );
    let all: Vec<Vec<f32>> = probed.iter().map(|&f| audio(f)).collect();
    let mut skipper = StillSkipper::new(config, all.clone()).unwrap();
    let (mut kinds, mut sent) = (Vec::new(), Vec::new());
    for f in 0..n {
        let reference = full.render(pose, &audio(f)).unwrap();
        let out = skipper.render(&mut skipping, pose, &audio(f)).unwrap();
        let worst = out
            .frame
            .image
            .data
            .iter()
            .zip(&reference.image.data)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        if probed.contains(&f) {
            assert!(worst <= config.threshold + 1e-6, "probe frame {f}: {worst}");
        } else {
            println!("frame {f} (no probe's audio): largest error {worst}");
        }
        if out.kind == FrameKind::Full {
            assert_eq!(out.frame, reference);
        } else {
            assert!(out.frame.head_pixels <= reference.head_pixels);
            sent.push(out.frame.head_pixels);
        }
        kinds.push(out.kind);
    }
    let moving = skipper.moving_pixels().unwrap();
    println!("{moving} of {head} head pixels re-rendered over {n} frames: {kinds:?}");
    assert!(0 < moving && moving < head, "{moving} of {head}");
    // The moving pixels, counted here: the head pixels within `margin` (a square) of one
    // whose colour spreads by more than the threshold over the first full frame (frame 0's,
    // which the probed frame 1 starts from) and the probes' renders.
    let rays = full.rays(pose);
    let mut spread: Vec<(f32, f32)> = full
        .render(pose, &audio(0))
        .unwrap()
        .image
        .gather(&rays.pixels)
        .into_iter()
        .map(|v| (v, v))
        .collect();
    for probe in &all {
        let rgb = full.run_rays(&rays, probe).unwrap().rgb;
        for (s, v) in spread.iter_mut().zip(rgb) {
            *s = (s.0.min(v), s.1.max(v));
        }
    }
    let w = full.intrinsics().width as usize;
    let hot: Vec<usize> = rays
        .pixels
        .iter()
        .zip(spread.chunks(3))
        .filter(|(_, s)| s.iter().any(|(lo, hi)| hi - lo > config.threshold))
        .map(|(&p, _)| p)
        .collect();
    let margin = config.margin as usize;
    let expected = rays
        .pixels
        .iter()
        .filter(|&&p| {
            hot.iter()
                .any(|&q| (p / w).abs_diff(q / w) <= margin && (p % w).abs_diff(q % w) <= margin)
        })
        .count();
    assert_eq!(moving, expected, "the moving pixels");
    assert!(
        sent.iter().all(|&s| s == moving),
        "a skipped frame sends the moving pixels' rays: {sent:?}"
    );
    for (f, k) in kinds.iter().enumerate() {
        let expected = match f % config.refresh {
            0 => FrameKind::Full,
            1 if f == 1 => FrameKind::Probed,
            _ => FrameKind::Partial,
        };
        assert_eq!(*k, expected, "frame {f}");
    }
    // A moving pose: every frame in full, identical to the full render.
    let track = default_track(&info, 4);
    let r = bench_track(
        &mut full,
        &mut skipping,
        "moving",
        &track,
        &audio,
        config,
        all.clone(),
    )
    .unwrap();
    assert_eq!((r.full_frames, r.psnr_vs_full, r.ray_share), (4, None, 1.0));
    // Settings out of range are refused.
    for bad in [
        SkipConfig {
            refresh: 0,
            ..config
        },
        SkipConfig {
            threshold: f32::NAN,
            ..config
        },
    ] {
        assert!(StillSkipper::new(bad, all.clone()).is_err());
    }
    assert!(StillSkipper::new(config, Vec::new()).is_err());
    // The render path: a still track through --poses with skipping on.
    let poses = run.root.join("still.json");
    let c2w: Vec<Vec<f32>> = (0..4)
        .map(|r| (0..4).map(|c| pose.col(c)[r]).collect())
        .collect();
    let frames: Vec<serde_json::Value> = (0..n)
        .map(|_| serde_json::json!({"img_id": 0, "transform_matrix": c2w, "aud_id": 0}))
        .collect();
    std::fs::write(
        &poses,
        serde_json::json!({"focal_len": info.spec.intrinsics.focal, "cx": info.spec.intrinsics.cx, "cy": info.spec.intrinsics.cy, "frames": frames}).to_string(),
    )
    .unwrap();
    let parsed = nldf_infer::poses::poses_from_transforms(&poses).unwrap();
    assert!(
        parsed.iter().all(|p| *p == pose),
        "{:?} vs {pose:?}",
        parsed[0]
    );
    let out = run.root.join("skip_render");
    let report = VideoJob {
        poses: Some(poses),
        skip: Some(config),
        ..job(&path, &wav, &out)
    }
    .plan()
    .unwrap()
    .render(|_| {})
    .unwrap();
    assert_eq!(report.full_frames, n.div_ceil(config.refresh));
    let mut skipper = StillSkipper::new(config, all).unwrap();
    for f in 0..n {
        let expected = skipper.render(&mut skipping, pose, &audio(f)).unwrap();
        let written = ImageRgb::load(&out.join(frame_file_name(f))).unwrap();
        assert_eq!(
            written.to_rgb8(),
            expected.frame.image.to_rgb8(),
            "frame {f}"
        );
    }
}
