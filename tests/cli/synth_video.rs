//! `nldf synth --video` (a test video whose truth is the synthetic dataset) and
//! `nldf bench prepare` (a prepared dataset scored against that truth), from the command line.

use std::path::Path;
use std::process::Command;

use nldf_core::image::ImageRgb;

use super::{args, nldf_ok, refused, s, scratch};

/// ffmpeg as `nldf synth --video` finds it; `None` (a skip) only outside CI.
fn ffmpeg() -> Option<std::path::PathBuf> {
    match nldf_prepare::tools::ffmpeg() {
        Ok(p) => Some(p),
        Err(e) => nldf_tests::tool_missing(format!("nldf synth --video needs ffmpeg: {e}")),
    }
}

/// What ffmpeg says decoding every frame of `video`: its log, with the stream lines and the
/// last `frame=` count.
fn decode_log(ffmpeg: &Path, video: &Path) -> String {
    let out = Command::new(ffmpeg)
        .args(["-nostdin", "-i"])
        .arg(video)
        .args(["-map", "0:v", "-map", "0:a", "-f", "null", "-"])
        .output()
        .unwrap();
    let log = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(
        out.status.success(),
        "ffmpeg cannot decode the video:\n{log}"
    );
    log
}

/// The recording's 30 frames (1.2 s at 25 fps) become an H.264 + AAC MP4 of 30 frames at
/// 25 fps whose first and last frames are the first and last PNGs; nothing else is left
/// beside it. The scene scored against itself passes every bar of `nldf bench prepare`,
/// which writes its JSON; with a black background it fails that bar alone, in one line.
#[test]
fn synth_video_writes_the_recording_as_an_mp4_that_bench_prepare_scores() {
    let Some(ffmpeg) = ffmpeg() else { return };
    let dir = scratch();
    let d = dir.path();
    let (scene, video) = (d.join("scene"), d.join("clips/clip.mp4"));
    nldf_ok(args(&[
        "synth",
        "--out",
        &s(&scene),
        "--size",
        "32",
        "--seconds",
        "1.2",
        "--supersample",
        "1",
        "--head",
        "second",
        "--max-yaw-deg",
        "30",
        "--video",
        &s(&video),
    ]));
    let names: Vec<_> = std::fs::read_dir(d.join("clips"))
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, ["clip.mp4"], "left beside the video: {names:?}");
    let log = decode_log(&ffmpeg, &video);
    assert!(
        log.contains("Video: h264") && log.contains("yuv420p") && log.contains("32x32"),
        "{log}"
    );
    assert!(
        log.contains("25 fps") && log.contains("Audio: aac"),
        "{log}"
    );
    let frames: usize = log
        .rsplit("frame=")
        .next()
        .and_then(|t| t.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no frame count in:\n{log}"));
    assert_eq!(frames, 30);
    let decoded = d.join("decoded");
    std::fs::create_dir(&decoded).unwrap();
    let out = Command::new(&ffmpeg)
        .args(["-nostdin", "-loglevel", "error", "-i"])
        .arg(&video)
        .args(["-start_number", "0"])
        .arg(decoded.join("%d.png"))
        .output()
        .unwrap();
    assert!(out.status.success());
    for k in [0, 29] {
        let a = ImageRgb::load(&decoded.join(format!("{k}.png"))).unwrap();
        let b = ImageRgb::load(&scene.join(format!("head_imgs/{k}.png"))).unwrap();
        let db = nldf_core::metrics::psnr(&a, &b).unwrap();
        assert!(db > 30.0, "frame {k}: {db:.1} dB from its PNG");
    }
    let scene_json = std::fs::read_to_string(scene.join("scene.json")).unwrap();
    assert!(scene_json.contains("\"max_yaw_deg\": 30.0"), "{scene_json}");

    let json = d.join("scores.json");
    let bench = |prepared: &Path| {
        args(&[
            "bench",
            "prepare",
            "--truth",
            &s(&scene),
            "--prepared",
            &s(prepared),
            "--out",
            &s(&json),
        ])
    };
    let out = nldf_ok(bench(&scene));
    let table = String::from_utf8_lossy(&out.stdout);
    assert_eq!(table.matches("| pass |").count(), 6, "{table}");
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(report["passed"], true);
    assert_eq!(report["scores"]["frames_compared"], 30);
    let dark = d.join("dark");
    nldf_tests::copy_dir(&scene, &dark);
    ImageRgb::filled(32, 32, [0.0; 3])
        .save_png(&dark.join("bc.png"))
        .unwrap();
    refused(
        "bench prepare of a dataset with a black background",
        &bench(&dark),
        &["1 of 6 bars failed", "background PSNR"],
        &[],
    );
}

/// `--video` is checked before any frame is rendered: an odd size (yuv420p needs even
/// ones) and a folder are refused, and no scene is written.
#[test]
fn synth_video_with_an_odd_size_or_a_folder_is_refused() {
    let dir = scratch();
    let d = dir.path();
    let scene = d.join("scene");
    let clip = s(&d.join("clip.mp4"));
    refused(
        "synth --video at an odd size",
        &args(&[
            "synth",
            "--out",
            &s(&scene),
            "--size",
            "33",
            "--video",
            &clip,
        ]),
        &["--video", "even --size", "33"],
        &[&scene, &d.join("clip.mp4")],
    );
    refused(
        "synth --video naming a folder",
        &args(&["synth", "--out", &s(&scene), "--video", &s(d)]),
        &["--video", "is a folder"],
        &[&scene],
    );
    // The camera's settings are the scene's: a camera inside the head's reach, or no focal
    // length, is refused before a frame is drawn.
    refused(
        "synth --camera-distance inside the head",
        &args(&["synth", "--out", &s(&scene), "--camera-distance", "0.3"]),
        &["camera_distance 0.3", ">= 0.5"],
        &[&scene],
    );
    refused(
        "synth --render-size 100000",
        &args(&["synth", "--out", &s(&scene), "--render-size", "100000"]),
        &["--render-size", "100000"],
        &[&scene],
    );
    refused(
        "synth --focal-at-128 0",
        &args(&["synth", "--out", &s(&scene), "--focal-at-128", "0"]),
        &["focal_at_128", "positive"],
        &[&scene],
    );
}

/// `--render-size` renders the scene at the larger size and shrinks it: every split's
/// images are the larger render filtered down (close to its 2 x 2 block means), the labels
/// are labels of the block they sit in, and the intrinsics, in the transforms files and in
/// `scene.json`, are halved; the shrunk scene loads as a dataset with all its splits.
#[test]
fn synth_render_size_shrinks_a_larger_render() {
    let dir = scratch();
    let scene = |name: &str, extra: &[&str]| {
        let out = dir.path().join(name);
        let o = s(&out);
        let mut a = vec!["synth", "--out", &o, "--seconds", "1", "--supersample", "1"];
        a.extend_from_slice(extra);
        nldf_ok(args(&a));
        out
    };
    let big = scene("big", &["--size", "64"]);
    let small = scene("small", &["--size", "32", "--render-size", "64"]);
    let ds = nldf_core::dataset::Dataset::load(&small).unwrap();
    assert!(!ds.train.is_empty() && !ds.val.is_empty());
    for split in ["train", "val", "novel", "voice", "sweep"] {
        let file = format!("transforms_{split}.json");
        let b = nldf_core::dataset::TransformsFile::load(&big.join(&file)).unwrap();
        let t = nldf_core::dataset::TransformsFile::load(&small.join(&file)).unwrap();
        assert!((t.focal_len - 0.5 * b.focal_len).abs() < 1e-4, "{file}");
        assert_eq!((t.cx, t.width), (16.0, Some(32)), "{file}");
        let id = t.frames[0].img_id;
        let img = |d: &Path, sub: &str| ImageRgb::load(&d.join(format!("{sub}/{id}.png"))).unwrap();
        let (shrunk, render) = (img(&small, "head_imgs"), img(&big, "head_imgs"));
        assert_eq!((shrunk.width, shrunk.height), (32, 32));
        let block = render.downscaled(2);
        let mse = (shrunk.data.iter().zip(&block.data))
            .map(|(a, b)| ((a - b) as f64).powi(2))
            .sum::<f64>()
            / block.data.len() as f64;
        let psnr = -10.0 * mse.log10();
        assert!(
            psnr > 30.0,
            "{file} img_id {id}: {psnr:.1} dB from the block means"
        );
        let (labels, full) = (img(&small, "regions"), img(&big, "regions"));
        for y in 0..32u32 {
            for x in 0..32u32 {
                let l = labels.get(x, y);
                let seen = (0..4).any(|k| full.get(2 * x + k % 2, 2 * y + k / 2) == l);
                assert!(
                    seen,
                    "{file} img_id {id}: label ({x}, {y}) is not of its block"
                );
            }
        }
    }
    let json = |d: &Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(d.join("scene.json")).unwrap()).unwrap()
    };
    let (sb, ss) = (json(&big), json(&small));
    assert_eq!(ss["intrinsics"]["width"], 32);
    assert_eq!(ss["config"]["size"], 32);
    let half = 0.5 * sb["intrinsics"]["focal"].as_f64().unwrap();
    assert!((ss["intrinsics"]["focal"].as_f64().unwrap() - half).abs() < 1e-4);
}
