//! The prepared-dataset scorer (`nldf_prepare::check`) end to end: a small synthetic scene
//! of each head, and a "prepared" dataset made from its truth as a perfect `nldf prepare`
//! would make it (the cameras moved by a similarity no method can observe, one frame
//! dropped, the parsing copied, landmarks around the true mouth, the background as JPEG),
//! scores within every bar; each planted fault fails its own bar and only that one; broken
//! files are one-line errors naming the file.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use glam::{DMat3, DVec3};
use nldf_core::dataset::{Split, TransformsFile};
use nldf_core::landmarks::{Landmarks, landmarks_from_regions};
use nldf_core::region::Region;
use nldf_core::synth::{HeadStyle, SynthConfig, generate, truth_labels_dir};
use nldf_prepare::align::{CameraPose, Similarity};
use nldf_prepare::check::{PrepareScores, score_prepared};
use nldf_prepare::held_out::{Carry, carry_held_out};
use nldf_tests::assert_one_line_naming;

/// The frame the fake prepared dataset drops.
const DROPPED: i64 = 7;

/// A 2 s scene of `head` at 64 x 64 turning up to 25°, made once per test process.
fn truth(head: HeadStyle) -> &'static Path {
    static DIRS: [OnceLock<PathBuf>; 2] = [OnceLock::new(), OnceLock::new()];
    DIRS[head as usize].get_or_init(|| {
        let dir = tempfile::Builder::new()
            .prefix("prepare-truth")
            .tempdir_in(env!("CARGO_TARGET_TMPDIR"))
            .unwrap()
            .keep();
        let out = dir.join("scene");
        let cfg = SynthConfig {
            seed: 5,
            seconds: 2.0,
            size: 64,
            supersample: 1,
            max_yaw_deg: 25.0,
            head,
            ..SynthConfig::default()
        };
        generate(&cfg, None, &out, false, &|| {}).unwrap();
        out
    })
}

/// The similarity the fake prepared cameras are seen through.
fn hidden() -> Similarity {
    Similarity {
        scale: 2.5,
        rotation: DMat3::from_axis_angle(DVec3::new(0.2, 1.0, -0.4).normalize(), 0.8),
        translation: DVec3::new(-0.3, 0.1, 0.7),
    }
}

/// A prepared dataset in AD-NeRF's layout made from the truth at `from`, at `to`.
fn fake_prepared(from: &Path, to: &Path, head: HeadStyle) {
    for sub in ["parsing", "ori_imgs"] {
        std::fs::create_dir_all(to.join(sub)).unwrap();
    }
    let inv = hidden().inverse();
    for split in [Split::Train, Split::Val] {
        let mut t = TransformsFile::load(&from.join(split.file_name())).unwrap();
        t.frames.retain(|f| f.img_id != DROPPED);
        for f in &mut t.frames {
            f.transform_matrix = inv
                .apply(&CameraPose::from_rows(&f.transform_matrix))
                .to_rows();
            let id = f.img_id;
            let parsing = format!("parsing/{id}.png");
            std::fs::copy(from.join(&parsing), to.join(&parsing)).unwrap();
            let labels = from.join(format!("{}/{id}.png", truth_labels_dir(head)));
            let regions: Vec<Region> = image::open(labels)
                .unwrap()
                .to_rgb8()
                .pixels()
                .map(|p| Region::from_label_color(p.0))
                .collect();
            let lms = landmarks_from_regions(&regions, 64).unwrap();
            std::fs::write(to.join(format!("ori_imgs/{id}.lms")), lms.to_text()).unwrap();
        }
        t.save(&to.join(split.file_name())).unwrap();
    }
    image::open(from.join("bc.png"))
        .unwrap()
        .save(to.join("bc.jpg"))
        .unwrap();
}

/// The names of the bars a score fails.
fn failed(scores: &PrepareScores) -> Vec<String> {
    scores
        .checks()
        .into_iter()
        .filter(|c| !c.pass)
        .map(|c| c.metric)
        .collect()
}

/// A copy of the prepared dataset `from` at `dir/name`, changed by `plant`, scored.
fn planted(from: &Path, dir: &Path, name: &str, plant: impl FnOnce(&Path)) -> PrepareScores {
    let to = dir.join(name);
    nldf_tests::copy_dir(from, &to);
    plant(&to);
    score_prepared(truth(HeadStyle::Second), &to).unwrap()
}

/// Rewrites every PNG of `dir/parsing` with `edit`.
fn edit_parsing(dir: &Path, edit: impl Fn(&mut image::RgbImage)) {
    for e in std::fs::read_dir(dir.join("parsing")).unwrap() {
        let path = e.unwrap().path();
        let mut img = image::open(&path).unwrap().to_rgb8();
        edit(&mut img);
        img.save(&path).unwrap();
    }
}

#[test]
fn a_prepared_dataset_made_from_the_truth_passes_every_bar() {
    for head in [HeadStyle::Standard, HeadStyle::Second] {
        let dir = tempfile::tempdir().unwrap();
        let prepared = dir.path().join("prepared");
        fake_prepared(truth(head), &prepared, head);
        let s = score_prepared(truth(head), &prepared).unwrap();
        println!("{head:?}: {s:?}");
        assert_eq!((s.frames_truth, s.frames_compared), (50, 49), "{s:?}");
        assert_eq!((s.frames_missing, s.frames_extra), (1, 0));
        // What is left of the hidden similarity is f32 rounding of the matrices.
        // Measured: 1.8e-6 degrees, 1.8e-8 of the distance, the scale 2.6e-8 off.
        assert!(s.poses.rotation_worst_deg < 2e-5, "{:?}", s.poses);
        assert!(s.poses.position_worst < 2e-7, "{:?}", s.poses);
        assert!((s.poses.scale - hidden().scale).abs() < 3e-7);
        assert_eq!((s.head_iou, s.head_iou_worst), (1.0, 1.0));
        assert!(s.bc_psnr_db > 35.0 && s.bc_pixels > 64 * 64 / 3, "{s:?}");
        assert!(s.lips_coverage > 0.85 && s.mouth_frames == 49, "{s:?}");
        assert!(failed(&s).is_empty(), "{:?}", failed(&s));
        let report = s.report(truth(head), &prepared);
        assert!(report.passed && report.checks.len() == 6);
    }
    // The second head's truth is itself a prepared dataset (landmarks, and bc.png where
    // bc.jpg is absent), and scores exactly.
    let t = truth(HeadStyle::Second);
    let s = score_prepared(t, t).unwrap();
    assert_eq!(s.frames_compared, 50);
    assert_eq!(s.poses.rotation_worst_deg, 0.0);
    assert_eq!(s.poses.position_worst, 0.0);
    assert_eq!((s.head_iou, s.bc_psnr_db), (1.0, 100.0));
    assert!(failed(&s).is_empty());
}

#[test]
fn each_planted_fault_fails_its_own_bar() {
    let head = HeadStyle::Second;
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good");
    fake_prepared(truth(head), &good, head);
    // One camera turned by 6 degrees.
    let s = planted(&good, dir.path(), "turned", |d| {
        let path = d.join(Split::Train.file_name());
        let mut t = TransformsFile::load(&path).unwrap();
        let mut pose = CameraPose::from_rows(&t.frames[10].transform_matrix);
        pose.rotation *= DMat3::from_rotation_y(6f64.to_radians());
        t.frames[10].transform_matrix = pose.to_rows();
        t.save(&path).unwrap();
    });
    assert_eq!(failed(&s), ["rotation error, worst"], "{s:?}");
    assert!((s.poses.rotation_worst_deg - 6.0).abs() < 0.2);
    // One camera 3 % of its distance off.
    let s = planted(&good, dir.path(), "shifted", |d| {
        let path = d.join(Split::Val.file_name());
        let mut t = TransformsFile::load(&path).unwrap();
        let mut pose = CameraPose::from_rows(&t.frames[1].transform_matrix);
        pose.centre.x += 0.03 / hidden().scale;
        t.frames[1].transform_matrix = pose.to_rows();
        t.save(&path).unwrap();
    });
    assert_eq!(failed(&s), ["camera position error, worst"], "{s:?}");
    // The head mask 4 pixels to the right.
    let s = planted(&good, dir.path(), "mask", |d| {
        edit_parsing(d, |img| {
            let old = img.clone();
            for (x, y, p) in img.enumerate_pixels_mut() {
                *p = *old.get_pixel(x.saturating_sub(4), y);
            }
        })
    });
    assert_eq!(failed(&s), ["head-mask IoU, pooled"], "{s:?}");
    // The background 20 levels darker: 20 log10(255 / 20) = 22.1 dB.
    let s = planted(&good, dir.path(), "dark", |d| {
        let mut bc = image::open(d.join("bc.jpg")).unwrap().to_rgb8();
        bc.pixels_mut()
            .for_each(|p| p.0 = p.0.map(|v| v.saturating_sub(20)));
        bc.save(d.join("bc.jpg")).unwrap();
    });
    assert_eq!(
        failed(&s),
        ["background PSNR, never-covered pixels"],
        "{s:?}"
    );
    // The lips 6 pixels below the mouth.
    let s = planted(&good, dir.path(), "lips", |d| {
        for e in std::fs::read_dir(d.join("ori_imgs")).unwrap() {
            let path = e.unwrap().path();
            let mut lms = Landmarks::load(&path).unwrap();
            lms.points.iter_mut().for_each(|p| p[1] += 6.0);
            std::fs::write(&path, lms.to_text()).unwrap();
        }
    });
    assert_eq!(failed(&s), ["lips cover the true mouth"], "{s:?}");
}

#[test]
fn broken_prepared_files_are_one_line_errors_naming_the_file() {
    let head = HeadStyle::Second;
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good");
    fake_prepared(truth(head), &good, head);
    let broken = |name: &str, damage: &dyn Fn(&Path)| -> String {
        let to = dir.path().join(name);
        nldf_tests::copy_dir(&good, &to);
        damage(&to);
        score_prepared(truth(head), &to).unwrap_err().to_string()
    };
    let small = broken("small", &|d| {
        image::RgbImage::new(32, 32)
            .save(d.join("parsing/3.png"))
            .unwrap()
    });
    assert_one_line_naming(&small, "parsing/3.png");
    assert!(
        small.contains("32x32") && small.contains("64x64"),
        "{small}"
    );
    let no_lms = broken("no_lms", &|d| {
        std::fs::remove_file(d.join("ori_imgs/12.lms")).unwrap()
    });
    assert_one_line_naming(&no_lms, "ori_imgs/12.lms");
    let no_bc = broken("no_bc", &|d| {
        std::fs::remove_file(d.join("bc.jpg")).unwrap()
    });
    assert_one_line_naming(&no_bc, "bc.jpg");
    let sheared = broken("sheared", &|d| {
        let path = d.join(Split::Val.file_name());
        let mut t = TransformsFile::load(&path).unwrap();
        t.frames[0].transform_matrix[0][1] += 0.5;
        t.save(&path).unwrap();
    });
    assert_one_line_naming(&sheared, "transforms_val.json");
    assert!(sheared.contains("not orthonormal"), "{sheared}");
    let no_val = broken("no_val", &|d| {
        std::fs::remove_file(d.join(Split::Val.file_name())).unwrap()
    });
    assert_one_line_naming(&no_val, "transforms_val.json");
    let truncated = broken("truncated", &|d| {
        std::fs::write(d.join("parsing/20.png"), b"\x89PNG").unwrap()
    });
    assert_one_line_naming(&truncated, "parsing/20.png");
}

/// The held-out splits carried into a prepared dataset whose poses are exact up to the
/// similarity: either way each camera is the scene's seen through that similarity, each frame has its image, parsing and `.lms`
/// (drawn from the exact labels for the standard head), the voice split its audio; a
/// dataset prepared at another focal length is refused, naming the flag.
#[test]
fn held_out_splits_carried_into_a_prepared_dataset_follow_its_world() {
    for head in [HeadStyle::Standard, HeadStyle::Second] {
        let dir = tempfile::tempdir().unwrap();
        let prepared = dir.path().join("prepared");
        fake_prepared(truth(head), &prepared, head);
        for how in [Carry::NearestFrame, Carry::Similarity] {
            let carried = carry_held_out(truth(head), &prepared, how).unwrap();
            assert_eq!(carried, [Split::Novel, Split::Voice, Split::Sweep]);
            assert_carried_exactly(truth(head), &prepared, &carried);
        }
        assert!(prepared.join("voice/aud.wav").is_file());
    }
    let dir = tempfile::tempdir().unwrap();
    let prepared = dir.path().join("prepared");
    fake_prepared(truth(HeadStyle::Second), &prepared, HeadStyle::Second);
    let path = prepared.join(Split::Train.file_name());
    let mut t = TransformsFile::load(&path).unwrap();
    t.focal_len *= 1.1;
    t.save(&path).unwrap();
    let e = carry_held_out(truth(HeadStyle::Second), &prepared, Carry::NearestFrame).unwrap_err();
    assert_one_line_naming(&e.to_string(), "transforms_train.json");
    assert_one_line_naming(&e.to_string(), "--focal");
}

/// Each carried camera of `splits` is the truth's seen through [`hidden`]'s inverse, and
/// each frame has its image, parsing and `.lms`.
fn assert_carried_exactly(scene: &Path, prepared: &Path, splits: &[Split]) {
    let inv = hidden().inverse();
    for &split in splits {
        let want = TransformsFile::load(&scene.join(split.file_name())).unwrap();
        let got = TransformsFile::load(&prepared.join(split.file_name())).unwrap();
        assert_eq!(got.frames.len(), want.frames.len());
        for (g, w) in got.frames.iter().zip(&want.frames) {
            let expect = inv.apply(&CameraPose::from_rows(&w.transform_matrix));
            let have = CameraPose::from_rows(&g.transform_matrix);
            assert!((have.centre - expect.centre).length() < 1e-5, "{split:?}");
            assert!(
                have.rotation.abs_diff_eq(expect.rotation, 1e-5),
                "{split:?}"
            );
            let id = g.img_id;
            for f in [format!("head_imgs/{id}.png"), format!("parsing/{id}.png")] {
                assert!(prepared.join(&f).is_file(), "{f}");
            }
            Landmarks::load(&prepared.join(format!("ori_imgs/{id}.lms"))).unwrap();
        }
    }
}

/// With the prepared poses of the held-out frames nudged off the similarity, a `voice`
/// frame carried from its nearest frame gets the nudged prepared pose of the recorded frame
/// it repeats, and a `closer` or `farther` view that pose moved along its own axis; carried
/// by the similarity, the nudge shows as an error instead.
#[test]
fn nearest_frame_carry_starts_from_the_prepared_pose_of_the_frame_it_repeats() {
    let head = HeadStyle::Standard;
    let dir = tempfile::tempdir().unwrap();
    let prepared = dir.path().join("prepared");
    fake_prepared(truth(head), &prepared, head);
    let val_path = prepared.join(Split::Val.file_name());
    let mut val = TransformsFile::load(&val_path).unwrap();
    let nudge = DMat3::from_axis_angle(DVec3::new(1.0, -0.5, 0.3).normalize(), 0.03);
    for f in &mut val.frames {
        let mut p = CameraPose::from_rows(&f.transform_matrix);
        p.rotation *= nudge;
        p.centre += DVec3::new(0.004, -0.003, 0.002);
        f.transform_matrix = p.to_rows();
    }
    val.save(&val_path).unwrap();
    let nudged: Vec<(i64, CameraPose)> = (val.frames.iter())
        .map(|f| (f.img_id, CameraPose::from_rows(&f.transform_matrix)))
        .collect();
    let true_val = TransformsFile::load(&truth(head).join(Split::Val.file_name())).unwrap();
    let source_of = |camera: &CameraPose| -> Option<CameraPose> {
        let f = true_val.frames.iter().find(|f| {
            let p = CameraPose::from_rows(&f.transform_matrix);
            p.rotation.abs_diff_eq(camera.rotation, 1e-6)
        })?;
        (nudged.iter().find(|(id, _)| *id == f.img_id)).map(|(_, p)| *p)
    };
    let mut by_similarity_off = 0.0f64;
    for how in [Carry::NearestFrame, Carry::Similarity] {
        carry_held_out(truth(head), &prepared, how).unwrap();
        let voice_truth =
            TransformsFile::load(&truth(head).join(Split::Voice.file_name())).unwrap();
        let voice = TransformsFile::load(&prepared.join(Split::Voice.file_name())).unwrap();
        let mut checked = 0;
        for (t, g) in voice_truth.frames.iter().zip(&voice.frames) {
            let want = source_of(&CameraPose::from_rows(&t.transform_matrix))
                .expect("a voice frame repeats a held-out frame's pose");
            let got = CameraPose::from_rows(&g.transform_matrix);
            let off = (got.centre - want.centre).length()
                + (got.rotation - want.rotation)
                    .to_cols_array()
                    .iter()
                    .map(|v| v.abs())
                    .sum::<f64>();
            match how {
                Carry::NearestFrame => assert!(off < 1e-5, "voice img_id {}: {off}", g.img_id),
                Carry::Similarity => by_similarity_off = by_similarity_off.max(off),
            }
            checked += 1;
        }
        assert!(checked > 0);
        if how == Carry::NearestFrame {
            let novel_truth =
                TransformsFile::load(&truth(head).join(Split::Novel.file_name())).unwrap();
            let novel = TransformsFile::load(&prepared.join(Split::Novel.file_name())).unwrap();
            let mut dollies = 0;
            for (t, g) in novel_truth.frames.iter().zip(&novel.frames) {
                let Some(from) = source_of(&CameraPose::from_rows(&t.transform_matrix)) else {
                    continue;
                };
                let got = CameraPose::from_rows(&g.transform_matrix);
                assert!(
                    got.rotation.abs_diff_eq(from.rotation, 1e-5),
                    "img_id {}",
                    g.img_id
                );
                let shift = from.rotation.transpose() * (got.centre - from.centre);
                assert!(
                    shift.x.abs() + shift.y.abs() < 1e-5 * (1.0 + shift.z.abs()),
                    "{shift}"
                );
                assert!(shift.z.abs() > 1e-3, "img_id {}: not moved", g.img_id);
                dollies += 1;
            }
            assert!(dollies > 0, "no closer or farther view found");
        }
    }
    assert!(
        by_similarity_off > 1e-3,
        "the similarity hid the nudge: {by_similarity_off}"
    );
}
