//! The track step against synthetic feature tracks: points on a head-sized ellipsoid moved
//! with the clip's true head motion, each seen for a stretch of frames, with pixel noise,
//! some tracks sliding over the surface and some jumping. The landmark solution is made
//! wrong on purpose (a canonical face of the wrong depth and no face bundle), as
//! mediapipe's is on a face unlike a human one.

use glam::Vec2;

use crate::align::{CameraPose, TrackErrors, align_tracks};

use super::*;

/// Tracks that stay on their point.
const N_GOOD: usize = 150;
/// Tracks that slide over the surface, 0.1 px more each frame.
const N_SLIDING: usize = 15;
/// Tracks that jump 8 px away for one frame in ten.
const N_JUMPING: usize = 10;

/// A point on the front of a head-sized ellipsoid (semi-axes 8, 11, 9 cm, centred 4 cm
/// behind the face's origin): azimuth within 60 degrees and elevation within 45 degrees
/// of straight ahead, so it faces a camera in front.
fn head_point(rng: &mut ChaCha8Rng) -> Vec3 {
    let azimuth = rng.random_range(-1.05..1.05f32);
    let elevation = rng.random_range(-0.6..0.8f32);
    Vec3::new(
        0.08 * elevation.cos() * azimuth.sin(),
        0.11 * elevation.sin(),
        0.09 * elevation.cos() * azimuth.cos() - 0.04,
    )
}

/// Feature tracks over `clip` (see the module docs); the first [`N_GOOD`] are clean.
fn feature_tracks(clip: &Clip, noise_px: f32, seed: u64) -> Vec<TrackPoint> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = clip.frames.len();
    let mut out = Vec::new();
    for track in 0..(N_GOOD + N_SLIDING + N_JUMPING) as u32 {
        let point = head_point(&mut rng);
        // Centred anywhere, cut at the clip's ends: the ends are seen by fewer tracks.
        let length = rng.random_range(30..n);
        let centre = rng.random_range(0..n);
        let first = centre.saturating_sub(length / 2);
        let length = length.min(n - first);
        let slide = Vec2::from_angle(rng.random_range(0.0..std::f32::consts::TAU)) * 0.1;
        for (step, i) in (first..first + length).enumerate() {
            let camera = Camera {
                intrinsics: intrinsics(FOCAL),
                c2w: clip.truth[i],
            };
            let (x, y, _) = camera.project(point).expect("the head faces the camera");
            let noise = Vec2::new(gaussian(&mut rng), gaussian(&mut rng)) * noise_px;
            let fault = match track as usize {
                t if t < N_GOOD => Vec2::ZERO,
                t if t < N_GOOD + N_SLIDING => slide * step as f32,
                _ if step % 10 == 3 => Vec2::new(8.0, -5.0),
                _ => Vec2::ZERO,
            };
            let pixel = Vec2::new(x, y) + noise + fault;
            out.push(TrackPoint {
                frame: clip.frames[i].frame,
                track,
                pixel: pixel.to_array(),
            });
        }
    }
    out
}

/// The canonical face of the test with its depth stretched by `depth` about its mean.
fn stretched(face: &[Vec3], depth: f32) -> Vec<Vec3> {
    let z_mean = face.iter().map(|p| p.z).sum::<f32>() / face.len() as f32;
    face.iter()
        .map(|p| Vec3::new(p.x, p.y, z_mean + depth * (p.z - z_mean)))
        .collect()
}

fn poses(c2w: &[Mat4]) -> Vec<CameraPose> {
    c2w.iter()
        .map(|m| CameraPose::from_rows(&m.transpose().to_cols_array_2d()))
        .collect()
}

/// Errors of `c2w` against the truth after the similarity no method can observe.
fn aligned(c2w: &[Mat4], truth: &[Mat4]) -> TrackErrors {
    align_tracks(&poses(truth), &poses(c2w)).unwrap().errors
}

/// Everything the track tests share: a clip, a canonical face (wrong, for most) and
/// landmarks without the face bundle.
struct Scene {
    clip: Clip,
    wrong: Vec<Vec3>,
    weights: Vec<f32>,
    cfg: PoseConfig,
}

/// The scene with the canonical face's depth stretched by `depth`.
fn scene(depth: f32) -> Scene {
    let (face, weights) = synthetic_face(21);
    Scene {
        clip: clip(&face, 1.0, 0.5, 22),
        wrong: stretched(&face, depth),
        weights,
        cfg: with(|c| c.bundle_iterations = 0),
    }
}

impl Scene {
    fn solve(&self, tracks: &[TrackPoint]) -> CameraTrack {
        let k = intrinsics(FOCAL);
        solve_track(
            &self.clip.frames,
            tracks,
            &self.wrong,
            &self.weights,
            &k,
            &self.cfg,
        )
        .unwrap()
    }
}

#[test]
fn tracks_undo_a_biased_landmark_solution() {
    let scene = scene(1.3);
    let tracks = feature_tracks(&scene.clip, 0.2, 23);
    let landmarks = scene.solve(&[]);
    let tracked = scene.solve(&tracks);
    let before = aligned(&landmarks.c2w, &scene.clip.truth);
    let after = aligned(&tracked.c2w, &scene.clip.truth);
    eprintln!(
        "landmarks {before:?}\ntracks {after:?}, {} tracks used, residual {} px",
        tracked.tracks.tracks_used, tracked.tracks.residual_px
    );
    assert_eq!(landmarks.tracks, TrackSummary::default());
    assert!(before.rotation_mean_deg > 1.0, "{before:?}");
    assert!(tracked.tracks.bundled);
    assert!(after.rotation_mean_deg < 0.15, "{after:?}");
    assert!(after.rotation_worst_deg < 0.4, "{after:?}");
    assert!(after.position_worst < 0.005, "{after:?}");
    // The jumping and sliding tracks are dropped (all but the shortest sliding ones, which
    // their points can follow), the clean ones kept.
    assert!(
        (N_GOOD - 10..=N_GOOD + 3).contains(&tracked.tracks.tracks_used),
        "{}",
        tracked.tracks.tracks_used
    );
    assert_eq!(tracked.tracks.frames_on_landmarks, 0);
    // Frames that see no track take their landmark pose with their neighbours' correction.
    let gap = scene.clip.frames[60].frame..scene.clip.frames[65].frame;
    let lost: Vec<TrackPoint> = tracks
        .iter()
        .filter(|t| !gap.contains(&t.frame))
        .copied()
        .collect();
    let carried = scene.solve(&lost);
    let carried_errors = aligned(&carried.c2w, &scene.clip.truth);
    assert_eq!(carried.tracks.frames_on_landmarks, 5);
    assert!(
        carried_errors.rotation_worst_deg < 0.6,
        "{carried_errors:?}"
    );
    assert!((0.1..0.4).contains(&tracked.tracks.residual_px));
    for m in &tracked.c2w {
        assert_eq!(rigid_problem(m, 1e-5), None);
    }
}

/// The gauge: with landmarks that are right (the exact canonical face), the tracks'
/// cameras sit in the landmarks' world: the origin where the landmarks put it in each
/// camera, turned the same way on average, at the same distance.
#[test]
fn tracks_keep_the_landmark_world() {
    let scene = scene(1.0);
    let tracks = feature_tracks(&scene.clip, 0.2, 24);
    let landmarks = poses(&scene.solve(&[]).c2w);
    let tracked = poses(&scene.solve(&tracks).c2w);
    // The origin in camera space: R^T (0 - c).
    let origin = |p: &CameraPose| p.rotation.transpose() * -p.centre;
    let n = landmarks.len() as f64;
    let shift: f64 = landmarks
        .iter()
        .zip(&tracked)
        .map(|(l, t)| (origin(l) - origin(t)).length())
        .sum::<f64>()
        / n;
    let turn = crate::align::rotation_angle_deg(
        landmarks
            .iter()
            .zip(&tracked)
            .fold(glam::DMat3::ZERO, |m, (l, t)| {
                m + l.rotation * t.rotation.transpose()
            }),
    );
    let distance = |p: &[CameraPose]| p.iter().map(|c| c.centre.length()).sum::<f64>() / n;
    let ratio = distance(&tracked) / distance(&landmarks);
    eprintln!("origin shift {shift} m, mean turn {turn} deg, distance ratio {ratio}");
    assert!(shift < 0.002, "{shift}");
    assert!(turn < 0.1, "{turn}");
    assert!((ratio - 1.0).abs() < 0.002, "{ratio}");
}

#[test]
fn too_few_tracks_leave_the_landmarks() {
    let scene = scene(1.3);
    let landmarks = scene.solve(&[]);
    let tracks = feature_tracks(&scene.clip, 0.2, 25);
    let few: Vec<TrackPoint> = tracks.iter().filter(|t| t.track < 12).copied().collect();
    let off = PoseConfig {
        track_iterations: 0,
        ..scene.cfg.clone()
    };
    for (tracks, cfg) in [(&few, &scene.cfg), (&tracks, &off)] {
        let k = intrinsics(FOCAL);
        let got = solve_track(
            &scene.clip.frames,
            tracks,
            &scene.wrong,
            &scene.weights,
            &k,
            cfg,
        )
        .unwrap();
        assert_eq!(got.tracks, TrackSummary::default());
        assert_eq!(got.c2w, landmarks.c2w);
    }
}
