//! How close the track comes to the truth: the exact face, a wrong canonical face, a wrong
//! focal, smoothing, little motion.

use super::*;

#[test]
fn exact_face_gives_accurate_rigid_cameras() {
    let (face, weights) = synthetic_face(1);
    let clip = clip(&face, 1.0, 1.0, 2);
    let track = solve(&clip, &face, &weights, FOCAL, &PoseConfig::default());
    let raw = solve(
        &clip,
        &face,
        &weights,
        FOCAL,
        &with(|c| c.smooth_sigma_frames = 0.0),
    );
    let e = errors(&track.c2w, &clip.truth);
    let e_raw = errors(&raw.c2w, &clip.truth);
    let mean_px = track.reprojection_px.iter().sum::<f32>() / track.reprojection_px.len() as f32;
    eprintln!(
        "exact face: {e:?} (unsmoothed {e_raw:?}), spread {:.1} deg, reprojection {mean_px:.3} px",
        track.rotation_spread_deg
    );
    assert!(track.bundled);
    assert!(e.rotation_deg < 0.3, "{e:?}");
    // A camera 1 m away moves by the rotation error times 1 m: 0.3 deg is 0.52 %.
    assert!(e.position < 0.006, "{e:?}");
    assert!(e.distance < 0.002, "{e:?}");
    // 1 px of noise on each axis leaves sqrt(2) px of 2D error.
    assert!((1.2..1.6).contains(&mean_px), "{mean_px}");
    assert_eq!(track.c2w.len(), clip.frames.len());
    for m in track.c2w.iter().chain(&raw.c2w) {
        assert_eq!(rigid_problem(m, 1e-5), None);
    }
}

/// The distorted face of the bundle test, in the solver's gauge: the canonical with
/// per-point offsets of 5 mm RMS and its depth stretched by 15 %, then mapped back onto the
/// canonical by the least-squares similarity over the weighted points.
fn distorted_face(canonical: &[Vec3], weights: &[f32], seed: u64) -> Vec<Vec3> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let sigma = 0.005 / 3f32.sqrt();
    let z_mean = canonical.iter().map(|p| p.z).sum::<f32>() / canonical.len() as f32;
    let distorted: Vec<Vec3> = canonical
        .iter()
        .map(|p| {
            let jitter = Vec3::new(gaussian(&mut rng), gaussian(&mut rng), gaussian(&mut rng));
            let q = *p + sigma * jitter;
            Vec3::new(q.x, q.y, z_mean + 1.15 * (q.z - z_mean))
        })
        .collect();
    let used: Vec<usize> = (0..canonical.len()).filter(|&j| weights[j] > 0.0).collect();
    let pick = |pts: &[Vec3]| used.iter().map(|&j| pts[j].as_dvec3()).collect::<Vec<_>>();
    let ones = vec![1.0; used.len()];
    let gauge = fit_similarity(&pick(&distorted), &pick(canonical), &ones).unwrap();
    distorted
        .iter()
        .map(|p| gauge.apply(p.as_dvec3()).as_vec3())
        .collect()
}

/// RMS distance in mm between two faces over the landmarks `pick` selects.
fn face_rms_mm(a: &[Vec3], b: &[Vec3], pick: impl Fn(usize) -> bool) -> f32 {
    let d: Vec<f32> = (0..a.len())
        .filter(|&j| pick(j))
        .map(|j| (a[j] - b[j]).length_squared())
        .collect();
    1e3 * (d.iter().sum::<f32>() / d.len() as f32).sqrt()
}

#[test]
fn bundle_step_undoes_a_wrong_canonical_depth() {
    let (canonical, weights) = synthetic_face(3);
    let truth_face = distorted_face(&canonical, &weights, 4);
    let clip = clip(&truth_face, 1.0, 1.0, 5);
    let plain = solve(
        &clip,
        &canonical,
        &weights,
        FOCAL,
        &with(|c| c.bundle_iterations = 0),
    );
    let bundled = solve(&clip, &canonical, &weights, FOCAL, &PoseConfig::default());
    let (e_plain, e_bundled) = (
        errors(&plain.c2w, &clip.truth),
        errors(&bundled.c2w, &clip.truth),
    );
    let weighted = |j: usize| weights[j] > 0.0;
    let others = |j: usize| weights[j] == 0.0;
    eprintln!("distorted canonical: PnP {e_plain:?}, bundle {e_bundled:?}");
    eprintln!(
        "face RMS, weighted points {:.2} -> {:.2} mm, the others {:.2} -> {:.2} mm",
        face_rms_mm(&canonical, &truth_face, weighted),
        face_rms_mm(&bundled.face, &truth_face, weighted),
        face_rms_mm(&canonical, &truth_face, others),
        face_rms_mm(&bundled.face, &truth_face, others),
    );
    assert!(!plain.bundled && bundled.bundled);
    assert!(e_plain.rotation_deg > 1.0, "{e_plain:?}");
    assert!(e_bundled.rotation_deg < 0.4, "{e_bundled:?}");
    assert!(e_bundled.rotation_deg < e_plain.rotation_deg / 4.0);
    assert!(e_bundled.position < e_plain.position / 4.0);
    let before = face_rms_mm(&canonical, &truth_face, weighted);
    assert!(face_rms_mm(&bundled.face, &truth_face, weighted) < 0.1 * before);
    // Unweighted points follow the weighted ones' affine map: the stretch is undone, their
    // own 5 mm offsets cannot be (6.4 mm RMS before, 5.0 mm of it offsets).
    assert!(
        face_rms_mm(&bundled.face, &truth_face, others)
            < 0.9 * face_rms_mm(&canonical, &truth_face, others)
    );
}

#[test]
fn focal_half_off_keeps_rotations() {
    let (face, weights) = synthetic_face(6);
    let clip = clip(&face, 1.0, 1.0, 7);
    // A wrong focal scales the distance with it and bends the rotations through the wrong
    // perspective: shorter focals more (the face's depth relief looks twice as deep).
    for (scale, bar) in [(1.5, 1.0), (0.5, 3.5)] {
        let track = solve(
            &clip,
            &face,
            &weights,
            FOCAL * scale,
            &PoseConfig::default(),
        );
        let e = errors(&track.c2w, &clip.truth);
        let ratio: f64 = track
            .c2w
            .iter()
            .zip(&clip.truth)
            .map(|(m, t)| f64::from(m.w_axis.truncate().length() / t.w_axis.truncate().length()))
            .sum::<f64>()
            / clip.truth.len() as f64;
        eprintln!("focal x{scale}: {e:?}, distance ratio {ratio:.4}");
        assert!(e.rotation_deg < bar, "focal x{scale}: {e:?}");
        assert!(
            (ratio / f64::from(scale) - 1.0).abs() < 0.06,
            "focal x{scale}: distance ratio {ratio}"
        );
        for m in &track.c2w {
            assert_eq!(rigid_problem(m, 1e-5), None);
        }
    }
}

/// Rotation of frame `i`'s error `R_est R_true^T` as a rotation vector.
fn rotation_error(est: &Mat4, truth: &Mat4) -> glam::DVec3 {
    super::linalg::log_rotation(rotation(est) * rotation(truth).inverse())
}

/// RMS angle (degrees) by which the rotation error changes from one kept frame to the next.
fn jitter_deg(est: &[Mat4], truth: &[Mat4]) -> f64 {
    let errs: Vec<_> = est
        .iter()
        .zip(truth)
        .map(|(e, t)| rotation_error(e, t))
        .collect();
    let sum: f64 = errs
        .windows(2)
        .map(|w| (w[1] - w[0]).length_squared())
        .sum();
    (sum / (errs.len() - 1) as f64).sqrt().to_degrees()
}

/// How many frames the track trails the truth: the least-squares `L` in
/// `err_i = -L v_i`, `v_i` the true angular velocity (rotation vector per frame).
fn lag_frames(est: &[Mat4], truth: &[Mat4], frames: &[usize]) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for i in 1..est.len() - 1 {
        let span = (frames[i + 1] - frames[i - 1]) as f64;
        let v = super::linalg::log_rotation(
            rotation(&truth[i + 1]) * rotation(&truth[i - 1]).inverse(),
        ) / span;
        num -= rotation_error(&est[i], &truth[i]).dot(v);
        den += v.length_squared();
    }
    num / den
}

#[test]
fn smoothing_cuts_jitter_without_lag() {
    let (face, weights) = synthetic_face(8);
    let noisy = clip(&face, 1.0, 1.0, 9);
    let raw = solve(
        &noisy,
        &face,
        &weights,
        FOCAL,
        &with(|c| c.smooth_sigma_frames = 0.0),
    );
    let smooth = solve(&noisy, &face, &weights, FOCAL, &PoseConfig::default());
    let (j_raw, j_smooth) = (
        jitter_deg(&raw.c2w, &noisy.truth),
        jitter_deg(&smooth.c2w, &noisy.truth),
    );
    let (e_raw, e_smooth) = (
        errors(&raw.c2w, &noisy.truth),
        errors(&smooth.c2w, &noisy.truth),
    );
    let clean = clip(&face, 1.0, 0.0, 9);
    let track = solve(&clean, &face, &weights, FOCAL, &PoseConfig::default());
    let e_clean = errors(&track.c2w, &clean.truth);
    let lag = lag_frames(&track.c2w, &clean.truth, &kept_frames());
    eprintln!(
        "jitter {j_raw:.3} -> {j_smooth:.3} deg, error {:.3} -> {:.3} deg; noise-free: error {:.3} deg, lag {lag:.4} frames",
        e_raw.rotation_deg, e_smooth.rotation_deg, e_clean.rotation_deg
    );
    assert!(j_smooth < j_raw / 3.0);
    assert!(e_smooth.rotation_deg < 0.75 * e_raw.rotation_deg);
    // The peak angular speed is 1.6 deg per frame: a one-frame delay would cost about 1 deg.
    assert!(lag.abs() < 0.02, "lag {lag} frames");
    assert!(e_clean.rotation_deg < 0.15, "{e_clean:?}");
}

#[test]
fn little_motion_keeps_the_canonical_face_and_all_weights_may_be_one() {
    let (face, _) = synthetic_face(12);
    let ones = vec![1.0; face.len()];
    let still = clip(&face, 0.1, 1.0, 13);
    let track = solve(&still, &face, &ones, FOCAL, &PoseConfig::default());
    let e = errors(&track.c2w, &still.truth);
    eprintln!(
        "all weights 1, little motion: {e:?}, spread {:.2} deg",
        track.rotation_spread_deg
    );
    assert!(!track.bundled && track.rotation_spread_deg < 5.0);
    assert_eq!(track.face, face);
    assert!(e.rotation_deg < 0.1, "{e:?}");
    let moving = clip(&face, 1.0, 1.0, 14);
    let track = solve(
        &moving,
        &face,
        &ones,
        FOCAL,
        &with(|c| c.bundle_frames = 40),
    );
    let e = errors(&track.c2w, &moving.truth);
    eprintln!("all weights 1, moving: {e:?}");
    assert!(track.bundled);
    assert!(e.rotation_deg < 0.15, "{e:?}");
}

/// Five minutes at 25 fps; `cargo test --release -p nldf-prepare long_clip -- --ignored
/// --nocapture` prints the time (the debug build is too slow to be a unit test).
#[test]
#[ignore]
fn long_clip() {
    let (face, weights) = synthetic_face(20);
    for (name, weights) in [
        ("procrustes-like", weights),
        ("all weights 1", vec![1.0; face.len()]),
    ] {
        let clip = clip_of(7500 * 17 / 16, &face, 1.0, 1.0, 21);
        let start = std::time::Instant::now();
        let track = solve(&clip, &face, &weights, FOCAL, &PoseConfig::default());
        let seconds = start.elapsed().as_secs_f64();
        let e = errors(&track.c2w, &clip.truth);
        eprintln!(
            "{} frames, {name}, {} threads: {seconds:.2} s, {e:?}",
            clip.frames.len(),
            rayon::current_num_threads()
        );
        assert!(track.bundled && e.rotation_deg < 0.3, "{e:?}");
    }
}

/// The refined face keeps the canonical's centroid, scale and orientation (the gauge the
/// pixels leave free) after every bundle step, not only at convergence (where the prior
/// alone would hold it).
#[test]
fn bundle_step_keeps_the_canonical_gauge() {
    let (canonical, weights) = synthetic_face(3);
    let clip = clip(&distorted_face(&canonical, &weights, 4), 1.0, 1.0, 5);
    let used: Vec<usize> = (0..canonical.len()).filter(|&j| weights[j] > 0.0).collect();
    let pick = |pts: &[Vec3]| used.iter().map(|&j| pts[j].as_dvec3()).collect::<Vec<_>>();
    let ones = vec![1.0; used.len()];
    for steps in [1, 2, 30] {
        let track = solve(
            &clip,
            &canonical,
            &weights,
            FOCAL,
            &with(|c| c.bundle_iterations = steps),
        );
        let gauge = fit_similarity(&pick(&track.face), &pick(&canonical), &ones).unwrap();
        let turn = angle_between(gauge.rotation, DQuat::IDENTITY);
        let (scale, shift) = (gauge.scale - 1.0, gauge.translation.length());
        eprintln!("{steps} steps: scale {scale:.1e}, turn {turn:.1e} rad, shift {shift:.1e} m");
        assert!(track.bundled);
        assert!(
            scale.abs() < 1e-7 && turn < 1e-7 && shift < 1e-8,
            "{steps} steps: {gauge:?}"
        );
    }
}
