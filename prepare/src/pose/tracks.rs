//! Head pose from feature tracks: points on the head's surface followed from frame to
//! frame, which (unlike mediapipe's landmarks, a face model regressed onto the image) stay
//! fixed on the head, so their motion tells the head's rotation without a model's bias.
//!
//! [`refine_with_tracks`] starts from the landmark solution:
//! 1. key frames spread evenly over the clip; the tracks seen in at least
//!    [`MIN_KEY_VIEWS`] of them are triangulated from the landmark poses (the least-squares
//!    point nearest their rays, with a weak pull towards the ray's point nearest the head's
//!    origin, which only matters where the rays are nearly parallel);
//! 2. the track bundle (`track_bundle`: key poses and points, Huber's loss) runs in rounds,
//!    each dropping the tracks whose RMS residual exceeds `track_reject_factor` times the
//!    median track's (and `track_reject_floor_px`): tracks that slid over the surface or
//!    left it;
//! 3. the gauge the pixels leave free is set from the landmark solution: the rotation `Q`
//!    is the mean of `R_lm^T R_ba` over the key frames, and the scale `s` and offset `d`
//!    make the landmark world's origin sit where the landmarks put it in every key frame's
//!    camera (least squares of `R'_f u + s t_f = t_lm,f` in `u = -d` and `s`), so the
//!    head's size, distance and origin are the landmark solution's;
//! 4. every frame's pose by PnP against the kept points seen in it (Huber's loss,
//!    reweighted), from its landmark pose; a frame that sees fewer than
//!    [`MIN_FRAME_POINTS`] takes its landmark pose corrected as the solved frames around it
//!    were (`R = dR R_lm`, `t = t_lm + dt` with `dR = R_t R_lm^T`, `dt = t_t - t_lm`
//!    interpolated between them), so that the landmarks' bias does not jump in.
//!
//! The result is refused (`None`: the caller keeps the landmarks alone) when fewer than
//! `track_min_points` tracks survive, or when its rotations depart from the landmarks' by
//! more than [`MAX_DEPARTURE_DEG`] RMS (a bundle gone astray).

use std::collections::BTreeMap;

use glam::{DMat3, DQuat, DVec2, DVec3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::config::{PoseConfig, TrackSummary, key_frames};
use super::linalg::{angle_between, cholesky_solve, mean_rotation};
use super::pnp::{self, Pinhole, Pose};
use super::track_bundle::{Observation, TrackBundle, huber};

/// Fewest key frames a track must be seen in to enter the bundle.
pub const MIN_KEY_VIEWS: usize = 3;
/// Fewest kept tracks a key frame must see to stay in the bundle.
const MIN_KEY_POINTS: usize = 6;
/// Fewest kept tracks a frame must see for its own pose; else it takes its landmark pose
/// with the nearest solved frame's correction.
pub const MIN_FRAME_POINTS: usize = 8;
/// Largest RMS angle between the track and landmark rotations that is believed, degrees.
pub const MAX_DEPARTURE_DEG: f64 = 10.0;
/// Rounds of the track bundle, each after dropping the worst tracks.
const ROUNDS: usize = 4;
/// Reweighting rounds of each frame's PnP.
const PNP_ROUNDS: usize = 3;
/// Weight of the pull of a triangulated point towards the head, per ray: a ray pair must
/// part by about `sqrt(PULL)` radians (0.6 degrees) before their crossing outweighs it.
const PULL: f64 = 1e-4;

/// One feature track's position in one frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TrackPoint {
    /// Index of the frame in the video.
    pub frame: usize,
    /// The track: one point of the head, followed over the frames it is seen in.
    pub track: u32,
    /// Pixels (x right, y down).
    pub pixel: [f32; 2],
}

/// What the track step made.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct TrackSolution {
    /// One pose per solved frame, in the landmark solution's world.
    pub poses: Vec<Pose>,
    pub summary: TrackSummary,
}

/// One track's key-frame observations and its point.
struct Candidate {
    track: u32,
    views: Vec<(usize, DVec2)>,
    point: DVec3,
}

/// Refines the landmark poses `landmark` (one per entry of `frames`, the video frame
/// indices, increasing) with the feature `tracks` (see the module docs); `None` when the
/// tracks cannot be trusted.
pub(crate) fn refine_with_tracks(
    frames: &[usize],
    landmark: &[Pose],
    tracks: &[TrackPoint],
    cam: &Pinhole,
    cfg: &PoseConfig,
) -> Option<TrackSolution> {
    if cfg.track_iterations == 0 || frames.len() < 3 {
        return None;
    }
    let keys: Vec<usize> = key_frames(frames.len(), cfg.track_key_frames);
    let key_of: BTreeMap<usize, usize> = keys
        .iter()
        .enumerate()
        .map(|(k, &i)| (frames[i], k))
        .collect();
    let key_poses: Vec<Pose> = keys.iter().map(|&i| landmark[i]).collect();
    let mut candidates = key_candidates(tracks, &key_of, &key_poses, cam);
    let key_poses = bundle_rounds(&mut candidates, key_poses, cam, cfg)?;
    if candidates.len() < cfg.track_min_points.max(1) {
        return None;
    }
    let landmark_keys: Vec<Pose> = keys.iter().map(|&i| landmark[i]).collect();
    let gauge = fit_gauge(&key_poses, &landmark_keys)?;
    let departure = rms_angle_deg(
        &key_poses.iter().map(|p| gauge.pose(p)).collect::<Vec<_>>(),
        &landmark_keys,
    );
    if departure.is_nan() || departure > MAX_DEPARTURE_DEG {
        return None;
    }
    let points: BTreeMap<u32, DVec3> = candidates
        .iter()
        .map(|c| (c.track, gauge.point(c.point)))
        .collect();
    Some(solve_frames(frames, landmark, tracks, &points, cam, cfg))
}

/// The tracks seen in at least [`MIN_KEY_VIEWS`] key frames, triangulated from the key
/// poses; `key_of` maps a video frame to its key frame.
fn key_candidates(
    tracks: &[TrackPoint],
    key_of: &BTreeMap<usize, usize>,
    key_poses: &[Pose],
    cam: &Pinhole,
) -> Vec<Candidate> {
    let mut views: BTreeMap<u32, Vec<(usize, DVec2)>> = BTreeMap::new();
    for t in tracks {
        let finite = t.pixel.iter().all(|v| v.is_finite());
        if let (Some(&k), true) = (key_of.get(&t.frame), finite) {
            let pixel = DVec2::new(f64::from(t.pixel[0]), f64::from(t.pixel[1]));
            views.entry(t.track).or_default().push((k, pixel));
        }
    }
    views
        .into_par_iter()
        .filter_map(|(track, mut views)| {
            views.sort_by_key(|v| v.0);
            views.dedup_by_key(|v| v.0);
            if views.len() < MIN_KEY_VIEWS {
                return None;
            }
            let point = triangulate(&views, key_poses, cam)?;
            Some(Candidate {
                track,
                views,
                point,
            })
        })
        .collect()
}

/// The point nearest the rays of `views` (key frame, pixel) in the least-squares sense,
/// pulled weakly towards the middle view's ray point nearest the world's origin (see
/// [`PULL`]): `X = (sum P_i + n PULL I)^-1 (sum P_i c_i + n PULL x0)` with
/// `P_i = I - d_i d_i^T` for the ray from centre `c_i` along unit `d_i`. `None` when the
/// point is not in front of every camera.
fn triangulate(views: &[(usize, DVec2)], poses: &[Pose], cam: &Pinhole) -> Option<DVec3> {
    let ray = |(k, pixel): &(usize, DVec2)| {
        let pose = &poses[*k];
        let inverse = pose.rotation.inverse();
        let centre = -(inverse * pose.translation);
        let local = DVec3::new(
            (pixel.x - cam.cx) / cam.focal,
            (pixel.y - cam.cy) / cam.focal,
            1.0,
        );
        (centre, (inverse * local).normalize())
    };
    let (c0, d0) = ray(&views[views.len() / 2]);
    let x0 = c0 - c0.dot(d0) * d0;
    let pull = PULL * views.len() as f64;
    let mut a = DMat3::IDENTITY * pull;
    let mut b = x0 * pull;
    for v in views {
        let (c, d) = ray(v);
        let p = DMat3::IDENTITY - outer(d, d);
        a += p;
        b += p * c;
    }
    let point = a.inverse() * b;
    let in_front = views.iter().all(|(k, _)| {
        let p = poses[*k].rotation * point + poses[*k].translation;
        p.z > 0.0
    });
    (point.is_finite() && in_front).then_some(point)
}

/// The bundle's rounds over `candidates` (pruned in place to the kept tracks, their points
/// refined); returns the refined key poses, `None` when too few key frames stay observed.
fn bundle_rounds(
    candidates: &mut Vec<Candidate>,
    mut poses: Vec<Pose>,
    cam: &Pinhole,
    cfg: &PoseConfig,
) -> Option<Vec<Pose>> {
    for round in 0..ROUNDS {
        let mut seen = vec![0usize; poses.len()];
        candidates
            .iter()
            .flat_map(|c| &c.views)
            .for_each(|(k, _)| seen[*k] += 1);
        // Key frames that see too few tracks leave the bundle; `slot` renumbers the rest.
        let kept: Vec<usize> = (0..poses.len())
            .filter(|&k| seen[k] >= MIN_KEY_POINTS)
            .collect();
        if kept.len() < 3 {
            return None;
        }
        let mut slot = vec![usize::MAX; poses.len()];
        kept.iter().enumerate().for_each(|(s, &k)| slot[k] = s);
        let observations: Vec<Observation> = candidates
            .iter()
            .enumerate()
            .flat_map(|(j, c)| {
                let slot = &slot;
                c.views
                    .iter()
                    .filter(move |(k, _)| slot[*k] != usize::MAX)
                    .map(move |(k, pixel)| Observation {
                        key: slot[*k],
                        point: j,
                        pixel: *pixel,
                    })
            })
            .collect();
        let problem = TrackBundle {
            observations: &observations,
            cam: *cam,
            huber_px: f64::from(cfg.track_huber_px),
        };
        let start: Vec<Pose> = kept.iter().map(|&k| poses[k]).collect();
        let points: Vec<DVec3> = candidates.iter().map(|c| c.point).collect();
        let (refined, points) = problem.run(start, points, cfg.track_iterations);
        for (s, &k) in kept.iter().enumerate() {
            poses[k] = refined[s];
        }
        let rms = problem.point_rms(&refined, &points);
        let threshold = reject_threshold(&rms, cfg);
        let before = candidates.len();
        let mut kept_points = points.iter().zip(&rms);
        candidates.retain_mut(|c| {
            let (point, e) = kept_points.next().expect("one point and RMS per candidate");
            c.point = *point;
            *e <= threshold
        });
        if candidates.len() == before || round + 1 == ROUNDS {
            break;
        }
    }
    Some(poses)
}

/// `max(reject_factor * median, reject_floor_px)` of the tracks' RMS residuals.
fn reject_threshold(rms: &[f64], cfg: &PoseConfig) -> f64 {
    let mut sorted: Vec<f64> = rms.iter().copied().filter(|e| e.is_finite()).collect();
    sorted.sort_by(f64::total_cmp);
    let median = sorted.get(sorted.len() / 2).copied().unwrap_or(0.0);
    (f64::from(cfg.track_reject_factor) * median).max(f64::from(cfg.track_reject_floor_px))
}

/// The world change `X' = s Q X + d` that puts the bundle's world onto the landmark
/// solution's (see the module docs).
struct Gauge {
    scale: f64,
    rotation: DQuat,
    offset: DVec3,
}

impl Gauge {
    fn point(&self, x: DVec3) -> DVec3 {
        self.scale * (self.rotation * x) + self.offset
    }

    /// `R' = R Q^T`, `t' = s t - R' d`: the same projections in the new world.
    fn pose(&self, p: &Pose) -> Pose {
        let rotation = (p.rotation * self.rotation.inverse()).normalize();
        Pose {
            rotation,
            translation: self.scale * p.translation - rotation * self.offset,
        }
    }
}

/// The gauge of the module docs from the bundle's key poses and the landmark ones; `None`
/// when its scale is not positive and finite.
fn fit_gauge(bundle: &[Pose], landmark: &[Pose]) -> Option<Gauge> {
    let offsets: Vec<DQuat> = bundle
        .iter()
        .zip(landmark)
        .map(|(b, l)| l.rotation.inverse() * b.rotation)
        .collect();
    let rotation = mean_rotation(&offsets);
    // Normal equations of R'_f u + s t_f = t_lm,f in z = (u, s), 4 x 4.
    let mut a = [0.0; 16];
    let mut rhs = [0.0; 4];
    for (b, l) in bundle.iter().zip(landmark) {
        let r = DMat3::from_quat((b.rotation * rotation.inverse()).normalize());
        for row in 0..3 {
            let j = [r.row(row).x, r.row(row).y, r.row(row).z, b.translation[row]];
            for p in 0..4 {
                rhs[p] += j[p] * l.translation[row];
                for q in 0..4 {
                    a[p * 4 + q] += j[p] * j[q];
                }
            }
        }
    }
    cholesky_solve(&mut a, &mut rhs)?;
    let scale = rhs[3];
    (scale.is_finite() && scale > 0.0).then(|| Gauge {
        scale,
        rotation,
        offset: -DVec3::new(rhs[0], rhs[1], rhs[2]),
    })
}

/// RMS angle in degrees between two pose lists' rotations.
fn rms_angle_deg(a: &[Pose], b: &[Pose]) -> f64 {
    let sum: f64 = a
        .iter()
        .zip(b)
        .map(|(p, q)| angle_between(p.rotation, q.rotation).powi(2))
        .sum();
    (sum / a.len().max(1) as f64).sqrt().to_degrees()
}

/// Every frame's pose by reweighted PnP against the gauged `points` it sees.
fn solve_frames(
    frames: &[usize],
    landmark: &[Pose],
    tracks: &[TrackPoint],
    points: &BTreeMap<u32, DVec3>,
    cam: &Pinhole,
    cfg: &PoseConfig,
) -> TrackSolution {
    let mut seen: Vec<(Vec<DVec3>, Vec<DVec2>)> = vec![(Vec::new(), Vec::new()); frames.len()];
    for t in tracks
        .iter()
        .filter(|t| t.pixel.iter().all(|v| v.is_finite()))
    {
        if let (Ok(i), Some(x)) = (frames.binary_search(&t.frame), points.get(&t.track)) {
            seen[i].0.push(*x);
            seen[i]
                .1
                .push(DVec2::new(f64::from(t.pixel[0]), f64::from(t.pixel[1])));
        }
    }
    let delta = f64::from(cfg.track_huber_px);
    let solved: Vec<(Pose, bool, Vec<f64>)> = seen
        .par_iter()
        .zip(landmark)
        .map(|((xs, pixels), start)| {
            if xs.len() < MIN_FRAME_POINTS {
                return (*start, false, Vec::new());
            }
            let mut pose = *start;
            for _ in 0..PNP_ROUNDS {
                let weights = residuals(&pose, xs, pixels, cam)
                    .iter()
                    .map(|e| huber(*e, delta).1)
                    .collect::<Vec<_>>();
                match pnp::refine(pose, xs, pixels, &weights, cam, cfg.pnp_iterations) {
                    Some(p) => pose = p,
                    None => return (*start, false, Vec::new()),
                }
            }
            (pose, true, residuals(&pose, xs, pixels, cam))
        })
        .collect();
    let mut all: Vec<f64> = solved.iter().flat_map(|s| s.2.iter().copied()).collect();
    all.sort_by(f64::total_cmp);
    let own: Vec<Option<Pose>> = solved.iter().map(|s| s.1.then_some(s.0)).collect();
    TrackSolution {
        poses: carry_corrections(landmark, &own),
        summary: TrackSummary {
            bundled: true,
            tracks_used: points.len(),
            frames_on_landmarks: own.iter().filter(|p| p.is_none()).count(),
            residual_px: all.get(all.len() / 2).copied().unwrap_or(0.0) as f32,
        },
    }
}

/// `own` poses where present; elsewhere the landmark pose with the correction of the
/// solved frames on either side interpolated (the nearest one's beyond the ends; the
/// landmark pose itself when no frame is solved).
fn carry_corrections(landmark: &[Pose], own: &[Option<Pose>]) -> Vec<Pose> {
    let solved: Vec<usize> = (0..own.len()).filter(|&i| own[i].is_some()).collect();
    // The correction `(R_t R_lm^T, t_t - t_lm)` of solved frame `j`.
    let correction = |j: usize| {
        let p = own[j].expect("solved frames have their own pose");
        (
            p.rotation * landmark[j].rotation.inverse(),
            p.translation - landmark[j].translation,
        )
    };
    (0..own.len())
        .map(|i| {
            if let Some(p) = own[i] {
                return p;
            }
            let at = solved.partition_point(|&j| j < i);
            let (rotation, translation) = match (at.checked_sub(1), solved.get(at)) {
                (Some(k), Some(&after)) => {
                    let before = solved[k];
                    let w = (i - before) as f64 / (after - before) as f64;
                    let (ra, ta) = correction(before);
                    let (rb, tb) = correction(after);
                    (ra.slerp(rb, w), ta.lerp(tb, w))
                }
                (Some(k), None) => correction(solved[k]),
                (None, Some(&after)) => correction(after),
                (None, None) => return landmark[i],
            };
            Pose {
                rotation: (rotation * landmark[i].rotation).normalize(),
                translation: landmark[i].translation + translation,
            }
        })
        .collect()
}

/// Reprojection error lengths of `points` against `pixels` under `pose`, pixels (infinite
/// behind the camera).
fn residuals(pose: &Pose, points: &[DVec3], pixels: &[DVec2], cam: &Pinhole) -> Vec<f64> {
    points
        .iter()
        .zip(pixels)
        .map(|(x, u)| {
            cam.project(pose.rotation * *x + pose.translation)
                .map_or(f64::INFINITY, |p| (p - *u).length())
        })
        .collect()
}

/// `a b^T`.
fn outer(a: DVec3, b: DVec3) -> DMat3 {
    DMat3::from_cols(a * b.x, a * b.y, a * b.z)
}
