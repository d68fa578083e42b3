//! A dataset in AD-NeRF's exact convention: `parsing/` written as AD-NeRF writes it (BGR
//! labels through OpenCV, so on disk the head is blue, the neck green, the cloth red and the
//! background white), 68 landmarks per frame in `ori_imgs/<id>.lms`, and no nldf labels. The
//! mouth must come from the landmarks' lips, never from the neck.

use std::path::{Path, PathBuf};

use nldf_core::dataset::{Dataset, LABELS_DIR, PARSING_DIR, Split, save_regions_png};
use nldf_core::image::ImageRgb;
use nldf_core::landmarks::{Landmarks, N_LANDMARKS, OUTER_LIPS};
use nldf_core::region::{MouthSource, Region};
use nldf_train::trainers::data::TrainData;
use nldf_train::trainers::scores::frame_scores;
use nldf_train::trainers::teacher_trainer::TeacherRun;

use crate::util::{tiny_run_config, tiny_scene};

/// One frame's exact labels, kept from the synthetic scene before they are removed.
struct Truth {
    head: Vec<bool>,
    mouth: Vec<bool>,
    neck: Vec<bool>,
}

/// The tiny synthetic scene rewritten in AD-NeRF's convention. Each frame gets a neck (the
/// background pixels of the two rows under the head's lowest row, across its width) and a
/// cloth (every background pixel of the last three rows), and landmarks whose lips are an
/// ellipse through the exact mouth's bounding box. Returns the folder and each frame's
/// exact labels, by `img_id`.
fn adnerf_scene(dir: &Path) -> (PathBuf, Vec<Truth>) {
    let root = dir.join("scene");
    nldf_tests::copy_dir(tiny_scene(), &root);
    let ds = Dataset::load(&root).unwrap();
    let (w, h) = (ds.intrinsics.width, ds.intrinsics.height);
    std::fs::create_dir_all(root.join("ori_imgs")).unwrap();
    let mut truths = Vec::new();
    let mut frames: Vec<_> = ds.train.iter().chain(&ds.val).collect();
    frames.sort_by_key(|f| f.img_id);
    for (k, f) in frames.iter().enumerate() {
        assert_eq!(f.img_id as usize, k);
        let exact = ds.load_regions(f).unwrap().unwrap();
        let head: Vec<bool> = exact.iter().map(|r| r.is_head()).collect();
        let mouth: Vec<bool> = exact.iter().map(|r| *r == Region::Mouth).collect();
        let at = |p: usize| ((p % w as usize) as u32, (p / w as usize) as u32);
        let lowest = (0..head.len())
            .filter(|&p| head[p])
            .map(|p| at(p).1)
            .max()
            .unwrap();
        let cols: Vec<u32> = (0..head.len())
            .filter(|&p| head[p])
            .map(|p| at(p).0)
            .collect();
        let (c0, c1) = (*cols.iter().min().unwrap(), *cols.iter().max().unwrap());
        let mut labels: Vec<Region> = exact
            .iter()
            .map(|r| {
                if r.is_head() {
                    Region::Face
                } else {
                    Region::Background
                }
            })
            .collect();
        let mut neck = vec![false; head.len()];
        for p in 0..head.len() {
            let (i, j) = at(p);
            if head[p] {
                continue;
            }
            if j >= h - 3 {
                labels[p] = Region::Torso;
            } else if j > lowest && j <= lowest + 2 && (c0..=c1).contains(&i) {
                labels[p] = Region::Neck;
                neck[p] = true;
            }
        }
        assert!(neck.iter().any(|&n| n), "frame {k}: no room for a neck");
        save_regions_png(
            &root.join(format!("{PARSING_DIR}/{k}.png")),
            w,
            h,
            &labels,
            Region::parsing_color,
        )
        .unwrap();
        let m: Vec<(u32, u32)> = (0..mouth.len()).filter(|&p| mouth[p]).map(at).collect();
        assert!(!m.is_empty(), "frame {k}: no mouth");
        let (x0, x1) = (
            m.iter().map(|p| p.0).min().unwrap(),
            m.iter().map(|p| p.0).max().unwrap(),
        );
        let (y0, y1) = (
            m.iter().map(|p| p.1).min().unwrap(),
            m.iter().map(|p| p.1).max().unwrap(),
        );
        let (cx, cy) = ((x0 + x1) as f32 / 2.0, (y0 + y1) as f32 / 2.0);
        let (rx, ry) = ((x1 - x0) as f32 / 2.0 + 0.7, (y1 - y0) as f32 / 2.0 + 0.7);
        let mut points = vec![[cx, cy - 3.0 * ry]; N_LANDMARKS];
        for (n, slot) in OUTER_LIPS.enumerate() {
            let a = std::f32::consts::TAU * n as f32 / OUTER_LIPS.len() as f32;
            points[slot] = [cx + rx * a.cos(), cy + ry * a.sin()];
        }
        std::fs::write(
            root.join(format!("ori_imgs/{k}.lms")),
            Landmarks { points }.to_text(),
        )
        .unwrap();
        truths.push(Truth { head, mouth, neck });
    }
    std::fs::remove_dir_all(root.join(LABELS_DIR)).unwrap();
    (root, truths)
}

#[test]
fn adnerf_parsing_and_landmarks_put_the_mouth_on_the_mouth() {
    let dir = tempfile::tempdir().unwrap();
    let (root, truths) = adnerf_scene(dir.path());
    // AD-NeRF's colours on disk: blue head, green neck, red cloth, white background.
    let parsing = image::open(root.join(format!("{PARSING_DIR}/0.png")))
        .unwrap()
        .into_rgb8();
    let colours: std::collections::BTreeSet<[u8; 3]> = parsing.pixels().map(|p| p.0).collect();
    assert_eq!(
        colours.into_iter().collect::<Vec<_>>(),
        vec![[0, 0, 255], [0, 255, 0], [255, 0, 0], [255, 255, 255]]
    );

    let data = TrainData::open(&root, true).unwrap();
    let ds = &data.dataset;
    assert_eq!(ds.mouth_source(), MouthSource::Landmarks);
    let w = ds.intrinsics.width as usize;
    let train = ds.frames(Split::Train);
    let (mut on_mouth, mut all) = (0usize, 0usize);
    for (fi, f) in train.iter().enumerate() {
        let truth = &truths[f.img_id as usize];
        let regions = ds.load_regions(f).unwrap().unwrap();
        let head: Vec<bool> = regions.iter().map(|r| r.is_head()).collect();
        assert_eq!(
            head, truth.head,
            "frame {}: the head is not the parsing's blue",
            f.img_id
        );
        for (p, (r, neck)) in regions.iter().zip(&truth.neck).enumerate() {
            if *neck {
                assert_eq!(*r, Region::Neck, "frame {}: pixel {p}", f.img_id);
            }
        }
        // The trainer's mouth pixels: inside the landmarks' lips, on the exact mouth, never
        // on the neck.
        let mouth = &data.mouth_pixels[fi];
        assert!(!mouth.is_empty(), "frame {}: no mouth pixels", f.img_id);
        for &(i, j) in mouth {
            let p = j as usize * w + i as usize;
            assert!(
                !truth.neck[p],
                "frame {}: a mouth pixel on the neck",
                f.img_id
            );
            assert!(
                truth.head[p],
                "frame {}: a mouth pixel off the head",
                f.img_id
            );
            on_mouth += usize::from(truth.mouth[p]);
            all += 1;
        }
    }
    let share = on_mouth as f64 / all as f64;
    assert!(
        share > 0.5,
        "only {:.0} % of the mouth pixels are on the mouth",
        100.0 * share
    );

    // A teacher trains on it, its mouth rays on the mouth.
    let cfg = tiny_run_config(2);
    let mouth_fraction = cfg.train.mouth_fraction;
    assert!(mouth_fraction > 0.0);
    let run_dir = tempfile::tempdir().unwrap();
    let mut run = TeacherRun::create(run_dir.path(), cfg, &data).unwrap();
    let pixels = run.step_pixels(&data);
    let on_lips = pixels
        .iter()
        .filter(|(fi, i, j)| data.mouth_pixels[*fi].contains(&(*i, *j)))
        .count();
    assert!(
        on_lips as f32 >= 0.9 * mouth_fraction * pixels.len() as f32,
        "{on_lips} of {} rays on the mouth",
        pixels.len()
    );
    let (loss, _) = run.train_step(&data).unwrap();
    assert!(loss.is_finite());
}

#[test]
fn adnerf_mouth_psnr_scores_the_mouth_and_not_the_neck() {
    let dir = tempfile::tempdir().unwrap();
    let (root, truths) = adnerf_scene(dir.path());
    let ds = Dataset::load(&root).unwrap();
    let f = &ds.val[0];
    let truth = ds.load_image(f).unwrap();
    let regions = ds.load_regions(f).unwrap().unwrap();
    let exact = &truths[f.img_id as usize];
    let spoil = |mask: &[bool]| -> ImageRgb {
        let mut img = truth.clone();
        for (p, _) in mask.iter().enumerate().filter(|(_, m)| **m) {
            for c in 0..3 {
                img.data[3 * p + c] = 1.0 - img.data[3 * p + c];
            }
        }
        img
    };
    let cap = nldf_core::metrics::PSNR_CAP;
    // A wrong neck leaves the head and the mouth perfect.
    let s = frame_scores(&spoil(&exact.neck), &truth, Some(&regions)).unwrap();
    assert_eq!((s.head_psnr, s.mouth_psnr), (Some(cap), Some(cap)), "{s:?}");
    // A wrong mouth shows in the mouth's score, far below the head's.
    let s = frame_scores(&spoil(&exact.mouth), &truth, Some(&regions)).unwrap();
    let (head, mouth) = (s.head_psnr.unwrap(), s.mouth_psnr.unwrap());
    assert!(
        mouth < 15.0 && mouth + 3.0 < head,
        "mouth {mouth} dB, head {head} dB"
    );
    assert!(s.head_ssim.unwrap() < 1.0);
}

#[test]
fn a_dataset_without_labels_or_landmarks_says_its_mouth_is_unknown() {
    let dir = tempfile::tempdir().unwrap();
    let (root, _) = adnerf_scene(dir.path());
    std::fs::remove_dir_all(root.join("ori_imgs")).unwrap();
    let data = TrainData::open(&root, true).unwrap();
    assert_eq!(data.dataset.mouth_source(), MouthSource::Unknown);
    assert!(MouthSource::Unknown.describe().contains("no mouth PSNR"));
    assert!(data.mouth_pixels.iter().all(Vec::is_empty));
    // The head is still known: the parsing's blue.
    let regions = data
        .dataset
        .load_regions(&data.dataset.val[0])
        .unwrap()
        .unwrap();
    assert!(regions.iter().any(|r| r.is_head()));
    assert!(!regions.contains(&Region::Mouth));
}

#[test]
fn a_frame_without_its_landmarks_is_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let (root, _) = adnerf_scene(dir.path());
    std::fs::remove_file(root.join("ori_imgs/3.lms")).unwrap();
    let err = Dataset::load(&root).unwrap_err().to_string();
    assert!(err.contains("3.lms") && err.contains("missing"), "{err}");
    std::fs::write(root.join("ori_imgs/3.lms"), "1 2\n").unwrap();
    let ds = Dataset::load(&root).unwrap();
    let frame = ds
        .train
        .iter()
        .chain(&ds.val)
        .find(|f| f.img_id == 3)
        .unwrap();
    let err = ds.load_regions(frame).unwrap_err().to_string();
    assert!(err.contains("3.lms") && err.contains("68"), "{err}");
}
