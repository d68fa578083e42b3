//! `nldf prepare`: a synthetic head's test video prepared end to end, and every way a video
//! can be wrong refused in one line with nothing left behind. Needs ffmpeg and the face
//! environment (`nldf prepare --setup`, which the test command runs first); outside CI a
//! missing one skips, under CI it fails.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use super::{args, nldf, nldf_ok, refused, s, scratch};

/// ffmpeg, and whether the face environment is installed; `None` (a skip) only outside CI.
pub(super) fn tools() -> Option<PathBuf> {
    let ffmpeg = match nldf_prepare::tools::ffmpeg() {
        Ok(p) => p,
        Err(e) => return nldf_tests::tool_missing(format!("nldf prepare needs ffmpeg: {e}")),
    };
    let env = nldf_prepare::tools::face_env_dir().ok();
    if env
        .and_then(|d| nldf_prepare::face::FaceEnv::open(&d))
        .is_none()
    {
        return nldf_tests::tool_missing(
            "nldf prepare needs the face environment: run `nldf prepare --setup`",
        );
    }
    Some(ffmpeg)
}

/// Runs ffmpeg with `args` and asserts it succeeded.
pub(super) fn ffmpeg(program: &Path, args: &[&str]) {
    let out = Command::new(program)
        .args(["-hide_banner", "-nostdin", "-loglevel", "error", "-y"])
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "ffmpeg {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// A 6 s, 128 x 128 test video of the standard head turning up to 20 degrees, made once,
/// with its synthetic scene (the truth).
struct Clip {
    _dir: tempfile::TempDir,
    scene: PathBuf,
    video: PathBuf,
}

fn clip() -> &'static Clip {
    static C: OnceLock<Clip> = OnceLock::new();
    C.get_or_init(|| {
        let dir = scratch();
        let (scene, video) = synth_video(dir.path(), "128", "6");
        Clip {
            _dir: dir,
            scene,
            video,
        }
    })
}

/// `nldf synth` of the standard head turning up to 20 degrees, `size` pixels and `seconds`
/// long, into `dir`: the scene (the truth) and its video.
fn synth_video(dir: &Path, size: &str, seconds: &str) -> (PathBuf, PathBuf) {
    let (scene, video) = (dir.join("scene"), dir.join("clip.mp4"));
    nldf_ok(args(&[
        "synth",
        "--out",
        &s(&scene),
        "--size",
        size,
        "--seconds",
        seconds,
        "--supersample",
        "1",
        "--max-yaw-deg",
        "20",
        "--video",
        &s(&video),
    ]));
    (scene, video)
}

/// The test video becomes a dataset in AD-NeRF's layout that nldf loads, whose head masks
/// and background match the scene's truth (`nldf bench prepare`'s bars for them), and whose
/// cameras turn as the scene's do to within a few degrees; without `--size` its frames are
/// 128 x 128, the size `nldf train --data`'s recipe is measured at.
#[test]
fn prepare_turns_a_test_video_into_a_dataset_close_to_its_truth() {
    if tools().is_none() {
        return;
    }
    let c = clip();
    let dir = scratch();
    let out = dir.path().join("data");
    nldf_ok(args(&[
        "prepare",
        "--video",
        &s(&c.video),
        "--out",
        &s(&out),
    ]));
    for f in [
        "bc.jpg",
        "aud.wav",
        "aud.npy",
        "aud.json",
        "transforms_train.json",
        "transforms_val.json",
        "prepare.json",
        "head_imgs/0.jpg",
        "ori_imgs/0.jpg",
        "ori_imgs/0.lms",
        "parsing/0.png",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    assert!(!dir.path().join("data.part").exists());
    let ds = nldf_core::dataset::Dataset::load(&out).unwrap();
    assert_eq!(ds.train.len() + ds.val.len(), 150);
    assert_eq!((ds.intrinsics.width, ds.intrinsics.height), (128, 128));
    let report = dir.path().join("score.json");
    nldf(args(&[
        "bench",
        "prepare",
        "--truth",
        &s(&c.scene),
        "--prepared",
        &s(&out),
        "--out",
        &s(&report),
    ]));
    let scores: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let num = |v: &serde_json::Value| v.as_f64().unwrap_or_else(|| panic!("{scores}"));
    assert!(num(&scores["scores"]["head_iou"]) >= 0.9, "{scores}");
    assert!(num(&scores["scores"]["bc_psnr_db"]) >= 30.0, "{scores}");
    assert!(
        num(&scores["scores"]["poses"]["rotation_mean_deg"]) < 5.0,
        "{scores}"
    );
}

/// A dataset wanted smaller than the video is analysed at the video's size and shrunk: at
/// `--size 64` from the 128-pixel test video its poses are those of the dataset prepared at
/// 128, its landmarks and intrinsics half of theirs, its images 64 x 64.
#[test]
fn prepare_analyses_a_larger_video_at_its_own_size() {
    if tools().is_none() {
        return;
    }
    let c = clip();
    let dir = scratch();
    let prepared = |size: &str| {
        let out = dir.path().join(format!("data{size}"));
        nldf_ok(args(&[
            "prepare",
            "--video",
            &s(&c.video),
            "--out",
            &s(&out),
            "--size",
            size,
        ]));
        out
    };
    let (big, small) = (prepared("128"), prepared("64"));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(small.join("prepare.json")).unwrap())
            .unwrap();
    assert_eq!(report["size"], 64, "{report}");
    assert_eq!(report["analysed_at"], 128, "{report}");
    for f in [
        "bc.jpg",
        "ori_imgs/3.jpg",
        "head_imgs/3.jpg",
        "parsing/3.png",
    ] {
        let img = nldf_core::image::ImageRgb::load(&small.join(f)).unwrap();
        assert_eq!((img.width, img.height), (64, 64), "{f}");
    }
    for split in ["transforms_train.json", "transforms_val.json"] {
        let b = nldf_core::dataset::TransformsFile::load(&big.join(split)).unwrap();
        let t = nldf_core::dataset::TransformsFile::load(&small.join(split)).unwrap();
        assert!((t.focal_len - 0.5 * b.focal_len).abs() < 1e-3, "{split}");
        assert_eq!((t.cx, t.cy, t.width), (32.0, 32.0, Some(64)), "{split}");
        assert_eq!(t.frames.len(), b.frames.len(), "{split}");
        for (tf, bf) in t.frames.iter().zip(&b.frames) {
            assert_eq!(tf.img_id, bf.img_id);
            let same = (tf.transform_matrix.iter().flatten())
                .zip(bf.transform_matrix.iter().flatten())
                .all(|(a, b)| (a - b).abs() < 1e-5);
            assert!(same, "{split} img_id {}: the pose moved", tf.img_id);
        }
    }
    let lms = |d: &Path| nldf_core::landmarks::Landmarks::load(&d.join("ori_imgs/3.lms")).unwrap();
    for (p, q) in lms(&small).points.iter().zip(&lms(&big).points) {
        assert!((p[0] - 0.5 * q[0]).abs() < 1e-3 && (p[1] - 0.5 * q[1]).abs() < 1e-3);
    }
}

/// A video smaller than the pose size (256) is decoded again at 256 for the head's pose
/// alone: with the default the 128-pixel test video's `prepare.json` says so and its
/// cameras move, while its frames, background, parsing and landmarks stay byte for byte
/// those of the dataset prepared with `--pose-size 0`, the video's own. (What the larger
/// frames do for the poses is measured on the tuning and test videos, docs/prepare.md.)
#[test]
fn a_small_video_is_posed_from_its_frames_scaled_up() {
    if tools().is_none() {
        return;
    }
    let c = clip();
    let dir = scratch();
    let prepared = |name: &str, extra: &[&str]| {
        let out = dir.path().join(name);
        let (video, to) = (s(&c.video), s(&out));
        let mut a = vec!["prepare", "--video", &video, "--out", &to, "--size", "128"];
        a.extend(extra);
        nldf_ok(args(&a));
        out
    };
    let (larger, own) = (
        prepared("larger", &[]),
        prepared("own", &["--pose-size", "0"]),
    );
    let report = |d: &Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(d.join("prepare.json")).unwrap()).unwrap()
    };
    assert_eq!(report(&larger)["posed_at"], 256, "{}", report(&larger));
    assert_eq!(report(&own)["posed_at"], 128, "{}", report(&own));
    for f in [
        "bc.jpg",
        "ori_imgs/5.jpg",
        "ori_imgs/5.lms",
        "parsing/5.png",
        "head_imgs/5.jpg",
    ] {
        let (a, b) = (
            std::fs::read(larger.join(f)).unwrap(),
            std::fs::read(own.join(f)).unwrap(),
        );
        assert!(a == b, "{f} differs");
    }
    let pose = |d: &Path| {
        nldf_core::dataset::TransformsFile::load(&d.join("transforms_train.json"))
            .unwrap()
            .frames[5]
            .transform_matrix
    };
    assert_ne!(pose(&larger), pose(&own), "the cameras did not move");
}

/// A copy of `video` whose odd frames come half a frame late: a variable frame rate.
fn variable_rate_copy(ff: &Path, video: &Path, out: &Path) {
    ffmpeg(
        ff,
        &[
            "-i",
            &s(video),
            "-vf",
            "setpts='if(mod(N,2),N+0.5,N)/25/TB'",
            "-fps_mode",
            "passthrough",
            "-video_track_timescale",
            "1000",
            &s(out),
        ],
    );
}

/// Each broken video is refused in one line naming the file and what is wrong, and no
/// dataset (nor its scratch folder) is left behind.
#[test]
fn prepare_refuses_videos_it_cannot_train_on() {
    let Some(ff) = tools() else { return };
    let c = clip();
    let dir = scratch();
    let d = dir.path();
    let v = |name: &str| d.join(name);
    let src = s(&c.video);
    ffmpeg(
        &ff,
        &["-i", &src, "-an", "-c:v", "copy", &s(&v("silent.mp4"))],
    );
    ffmpeg(&ff, &["-i", &src, "-vn", &s(&v("voice.m4a"))]);
    let bytes = std::fs::read(&c.video).unwrap();
    std::fs::write(v("corrupt.mp4"), &bytes[bytes.len() / 3..]).unwrap();
    ffmpeg(&ff, &["-i", &src, "-t", "2", &s(&v("short.mp4"))]);
    variable_rate_copy(&ff, &c.video, &v("vfr.mp4"));
    let bc = s(&c.scene.join("bc.png"));
    ffmpeg(
        &ff,
        &[
            "-loop",
            "1",
            "-i",
            &bc,
            "-i",
            &src,
            "-map",
            "0:v",
            "-map",
            "1:a",
            "-t",
            "6",
            "-r",
            "25",
            "-pix_fmt",
            "yuv420p",
            &s(&v("empty.mp4")),
        ],
    );
    ffmpeg(
        &ff,
        &[
            "-i",
            &src,
            "-i",
            &src,
            "-filter_complex",
            "[0:v][1:v]hstack,pad=256:256:0:64",
            "-map",
            "0:a",
            &s(&v("two.mp4")),
        ],
    );
    let out = v("data");
    let cases: [(&str, &str, &[&str]); 7] = [
        (
            "no audio track",
            "silent.mp4",
            &["silent.mp4", "no audio track"],
        ),
        (
            "an audio-only file",
            "voice.m4a",
            &["voice.m4a", "audio only"],
        ),
        (
            "a corrupt MP4",
            "corrupt.mp4",
            &["corrupt.mp4", "not a readable video"],
        ),
        (
            "a clip too short",
            "short.mp4",
            &["short.mp4", "too short to train"],
        ),
        (
            "a variable frame rate",
            "vfr.mp4",
            &["vfr.mp4", "variable frame rate"],
        ),
        ("no face", "empty.mp4", &["empty.mp4", "no face"]),
        ("two faces", "two.mp4", &["two.mp4", "two faces"]),
    ];
    for (case, file, needles) in cases {
        refused(
            case,
            &args(&[
                "prepare",
                "--video",
                &s(&v(file)),
                "--out",
                &s(&out),
                "--size",
                "128",
            ]),
            needles,
            &[&out, &v("data.part")],
        );
    }
}

/// Settings no video can be prepared with are refused in one line naming the flag, before
/// the video is read or the face environment installed (no tools needed), and nothing is
/// written: a size of 100000 pixels once asked for 30 GB and aborted.
#[test]
fn prepare_refuses_settings_it_cannot_use() {
    let dir = scratch();
    let out = dir.path().join("data");
    let video = s(&dir.path().join("clip.mp4"));
    let cases: [(&[&str], &[&str]); 8] = [
        (&["--size", "0"], &["--size 0", "32..=2048"]),
        (&["--size", "100000"], &["--size 100000", "32..=2048"]),
        (&["--analysis-size", "5000"], &["--analysis-size 5000"]),
        (&["--pose-size", "7"], &["--pose-size 7"]),
        (&["--seconds", "0"], &["--seconds 0", "> 0"]),
        (&["--start=-1"], &["--start -1", ">= 0"]),
        (&["--focal", "0"], &["--focal 0", "> 0"]),
        (&["--fps", "0"], &["--fps 0", "1..=120"]),
    ];
    let o = s(&out);
    for (flags, needles) in cases {
        let mut a = vec!["prepare", "--video", &video, "--out", &o];
        a.extend_from_slice(flags);
        refused(&flags.join(" "), &args(&a), needles, &[&out]);
    }
}

/// `--fps` resamples to a constant rate: the 25 frames/s test video at 12.5 gives half its
/// frames, written at 12.5 frames/s, and a variable-rate copy of it, refused without the
/// flag, is taken with `--fps 25`.
#[test]
fn prepare_resamples_to_the_fps_asked_for() {
    let Some(ff) = tools() else { return };
    let c = clip();
    let dir = scratch();
    let vfr = dir.path().join("vfr.mp4");
    variable_rate_copy(&ff, &c.video, &vfr);
    let prepare = |video: &Path, name: &str, fps: &str| {
        let out = dir.path().join(name);
        nldf_ok(args(&[
            "prepare",
            "--video",
            &s(video),
            "--out",
            &s(&out),
            "--size",
            "128",
            "--fps",
            fps,
            "--min-frames",
            "50",
        ]));
        nldf_core::dataset::Dataset::load(&out).unwrap()
    };
    let half = prepare(&c.video, "half", "12.5");
    assert_eq!(half.train.len() + half.val.len(), 75);
    let t =
        nldf_core::dataset::TransformsFile::load(&dir.path().join("half/transforms_train.json"))
            .unwrap();
    assert_eq!(t.fps, Some(12.5));
    let steady = prepare(&vfr, "steady", "25");
    let n = steady.train.len() + steady.val.len();
    assert!(
        (148..=152).contains(&n),
        "{n} frames from 6 s at 25 frames/s"
    );
}

/// A face that leaves the picture for a few frames: those frames are dropped and counted,
/// and the rest make the dataset.
#[test]
fn prepare_drops_the_frames_where_the_face_leaves_the_picture() {
    let Some(ff) = tools() else { return };
    let c = clip();
    let dir = scratch();
    let moved = dir.path().join("moved.mp4");
    // Frames 60-69 slide the picture 100 pixels left: the head leaves it.
    ffmpeg(
        &ff,
        &[
            "-i",
            &s(&c.video),
            "-vf",
            "pad=256:128:64:0,crop=128:128:'if(between(n,60,69),164,64)':0",
            "-c:a",
            "copy",
            &s(&moved),
        ],
    );
    let out = dir.path().join("data");
    let log = nldf_ok(args(&[
        "prepare",
        "--video",
        &s(&moved),
        "--out",
        &s(&out),
        "--size",
        "128",
    ]));
    let text = String::from_utf8_lossy(&log.stdout);
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("prepare.json")).unwrap()).unwrap();
    let dropped: Vec<u64> = report["dropped"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_u64().unwrap())
        .collect();
    assert!(
        (8..=12).contains(&dropped.len()) && dropped.iter().all(|&i| (58..72).contains(&i)),
        "dropped {dropped:?}\n{text}"
    );
    assert!(
        text.contains(&format!("{} dropped", dropped.len())),
        "{text}"
    );
    assert!(!out.join("ori_imgs/65.lms").exists());
}

/// At 256 pixels and up the face helper follows each corner it finds back through the
/// frames before it too, so a clip's first frames see as many feature tracks as the rest
/// (going forward only, they saw the first detection's few: about 0.7 of the median frame's
/// count on this clip, a quarter of it on the standard head's 512 test video).
#[test]
fn the_first_frames_see_the_tracks_found_after_them() {
    let Some(ff) = tools() else { return };
    let dir = scratch();
    let (_, video) = synth_video(dir.path(), "256", "4");
    let frames = dir.path().join("frames");
    std::fs::create_dir_all(&frames).unwrap();
    let pattern = s(&frames.join("%d.jpg"));
    ffmpeg(
        &ff,
        &[
            "-i",
            &s(&video),
            "-q:v",
            "1",
            "-start_number",
            "0",
            &pattern,
        ],
    );
    let n = std::fs::read_dir(&frames).unwrap().count();
    let env_dir = nldf_prepare::tools::face_env_dir().unwrap();
    let env = nldf_prepare::face::FaceEnv::open(&env_dir).unwrap();
    let out = env
        .run_frames(&frames, n, &dir.path().join("face"), 0.5, |_| {})
        .unwrap();
    let mut seen = vec![0usize; n];
    for t in &out.tracks {
        seen[t.frame] += 1;
    }
    let first = seen[..3].iter().sum::<usize>() as f64 / 3.0;
    let mut sorted = seen.clone();
    sorted.sort_unstable();
    let median = sorted[n / 2] as f64;
    assert!(
        median > 20.0 && first >= 0.9 * median,
        "tracks seen per frame: {seen:?}"
    );
}
