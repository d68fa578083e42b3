//! Inputs the solver must refuse or survive, and its small helpers.

use super::*;

/// Everything `solve_track` takes, owned, so that a case can spoil one part.
#[derive(Clone)]
struct Inputs {
    frames: Vec<FrameLandmarks>,
    canonical: Vec<Vec3>,
    weights: Vec<f32>,
    k: Intrinsics,
    cfg: PoseConfig,
}

impl Inputs {
    fn solve(&self) -> Result<CameraTrack> {
        solve_track(
            &self.frames,
            &[],
            &self.canonical,
            &self.weights,
            &self.k,
            &self.cfg,
        )
    }

    fn first(&self, weighted: bool) -> usize {
        self.weights
            .iter()
            .position(|w| (*w > 0.0) == weighted)
            .unwrap()
    }
}

type Spoil = fn(&mut Inputs);

/// Each case spoils valid inputs one way; each must be an argument error.
const BAD: [(&str, Spoil); 19] = [
    ("no frames", |i| i.frames.clear()),
    ("five weighted points", |i| {
        let extra: Vec<usize> = (0..i.weights.len())
            .filter(|&j| i.weights[j] > 0.0)
            .skip(5)
            .collect();
        extra.iter().for_each(|&j| i.weights[j] = 0.0);
    }),
    ("no weighted points", |i| i.weights.fill(0.0)),
    ("flat canonical", |i| {
        i.canonical.iter_mut().for_each(|p| p.z = 0.0)
    }),
    ("NaN canonical", |i| {
        let j = i.first(true);
        i.canonical[j].z = f32::NAN;
    }),
    ("negative weight", |i| {
        let j = i.first(false);
        i.weights[j] = -0.1;
    }),
    ("weights short", |i| i.weights.truncate(467)),
    ("zero focal", |i| i.k.focal = 0.0),
    ("NaN focal", |i| i.k.focal = f32::NAN),
    ("infinite cx", |i| i.k.cx = f32::INFINITY),
    ("zero prior", |i| i.cfg.bundle_prior_mm = 0.0),
    ("NaN sigma", |i| i.cfg.smooth_sigma_frames = f32::NAN),
    ("NaN weighted landmark", |i| {
        let j = i.first(true);
        i.frames[3].points[j][0] = f32::NAN;
    }),
    ("infinite unweighted landmark", |i| {
        let j = i.first(false);
        i.frames[5].points[j][1] = f32::INFINITY;
    }),
    ("a landmark missing", |i| i.frames[2].points.truncate(467)),
    ("frames out of order", |i| i.frames.swap(4, 5)),
    ("a frame twice", |i| i.frames[6].frame = i.frames[5].frame),
    ("landmarks on one pixel", |i| {
        i.frames[7].points.fill([100.0, 100.0])
    }),
    ("landmarks on a line", |i| {
        i.frames[8]
            .points
            .iter_mut()
            .enumerate()
            .for_each(|(j, p)| *p = [j as f32, j as f32]);
    }),
];

type Warp = fn([f32; 2]) -> [f32; 2];

/// Finite but absurd landmarks in frame 1: each may be refused or solved, never a panic or
/// a NaN.
const ABSURD: [(&str, Warp); 4] = [
    ("1e30 times", |p| [p[0] * 1e30, p[1] * 1e30]),
    ("1e-30 times", |p| [p[0] * 1e-30, p[1] * 1e-30]),
    ("mirrored", |p| [512.0 - p[0], p[1]]),
    ("transposed", |p| [p[1], p[0]]),
];

#[test]
fn degenerate_input_is_an_error_never_a_panic_or_nan() {
    let (canonical, weights) = synthetic_face(15);
    let mut frames = clip(&canonical, 1.0, 1.0, 16).frames;
    frames.truncate(12);
    let valid = Inputs {
        frames,
        canonical,
        weights,
        k: intrinsics(FOCAL),
        cfg: PoseConfig::default(),
    };
    assert!(valid.solve().is_ok());
    for (name, spoil) in BAD {
        let mut inputs = valid.clone();
        spoil(&mut inputs);
        match inputs.solve() {
            Err(Error::Argument(message)) => eprintln!("{name}: {message}"),
            other => panic!("{name}: expected an argument error, got {other:?}"),
        }
    }
    for (name, warp) in ABSURD {
        let mut inputs = valid.clone();
        inputs.frames[1]
            .points
            .iter_mut()
            .for_each(|p| *p = warp(*p));
        let result = inputs.solve();
        eprintln!(
            "{name}: {:?}",
            result.as_ref().map(|t| t.reprojection_px[1])
        );
        if let Ok(track) = result {
            assert!(
                track.c2w.iter().all(|m| rigid_problem(m, 1e-4).is_none()),
                "{name}"
            );
            assert!(
                track.reprojection_px.iter().all(|e| e.is_finite()),
                "{name}"
            );
        }
    }
}

#[test]
fn config_defaults_round_trip_and_bad_fields_are_named() {
    let parsed: PoseConfig = serde_json::from_str("{}").unwrap();
    assert_eq!(parsed, PoseConfig::default());
    let text = serde_json::to_string(&PoseConfig::default()).unwrap();
    assert_eq!(
        serde_json::from_str::<PoseConfig>(&text).unwrap(),
        PoseConfig::default()
    );
    assert!(serde_json::from_str::<PoseConfig>(r#"{"smoothing": 2}"#).is_err());
    let message = with(|c| c.bundle_frames = 1)
        .validate()
        .unwrap_err()
        .to_string();
    assert!(message.contains("bundle_frames"), "{message}");
    for reach in [-0.1, 2.5, f32::NAN] {
        let message = with(|c| c.track_reach = reach)
            .validate()
            .unwrap_err()
            .to_string();
        assert!(message.contains("track_reach"), "{reach}: {message}");
    }
    assert!(with(|c| c.track_reach = 0.0).validate().is_ok());
}

#[test]
fn key_frames_spread_evenly_and_keep_both_ends() {
    assert_eq!(key_frames(10, 4), vec![0, 3, 6, 9]);
    assert_eq!(key_frames(5, 100), vec![0, 1, 2, 3, 4]);
    assert_eq!(key_frames(1, 100), vec![0]);
    let long = key_frames(7500, 100);
    assert_eq!((long.len(), long[0], long[99]), (100, 0, 7499));
    assert!(long.windows(2).all(|w| (75..=76).contains(&(w[1] - w[0]))));
}
