//! The solver against synthetic clips: a seeded face-like cloud moved by a smooth head
//! motion, projected with nldf-core's `Camera::project` (the definition of a correct track)
//! and jittered by seeded pixel noise.

use glam::{DQuat, Mat3, Mat4, Quat, Vec3};
use nldf_core::camera::{Camera, Intrinsics, look_at, rigid_problem};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::linalg::{angle_between, fit_similarity};
use super::*;

mod accuracy;
mod input;
mod tracks;

const FOCAL: f32 = 1320.0;
const DISTANCE: f32 = 1.0;
const N_FRAMES: usize = 150;

fn intrinsics(focal: f32) -> Intrinsics {
    Intrinsics {
        focal,
        cx: 256.0,
        cy: 256.0,
        width: 512,
        height: 512,
    }
}

fn gaussian(rng: &mut ChaCha8Rng) -> f32 {
    let u1: f32 = rng.random_range(1e-7..1.0);
    let u2: f32 = rng.random();
    (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos()
}

/// 468 points on a face-sized half-ellipsoid with a nose (metres, y up, z towards the
/// camera; depth from -3 cm at the sides to 8 cm at the nose tip, as mediapipe's canonical
/// face), and weights: about a quarter of the points, above the mouth, get 0.01..0.08
/// (mediapipe's procrustes weights are of that size); the rest 0.
fn synthetic_face(seed: u64) -> (Vec<Vec3>, Vec<f32>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut face = Vec::with_capacity(468);
    let mut weights = Vec::with_capacity(468);
    while face.len() < 468 {
        let (x, y) = (
            rng.random_range(-0.078..0.078f32),
            rng.random_range(-0.1..0.1f32),
        );
        if (x / 0.078).powi(2) + (y / 0.1).powi(2) > 1.0 {
            continue;
        }
        let dome = 0.09
            * (1.0 - (x / 0.08).powi(2) - (y / 0.13).powi(2))
                .max(0.0)
                .sqrt();
        let nose = 0.025 * (-(x * x + (y + 0.01).powi(2)) / (2.0 * 0.012 * 0.012)).exp();
        face.push(Vec3::new(x, y, dome + nose - 0.03));
        let rigid = y > -0.02 && face.len() % 4 == 0;
        weights.push(if rigid {
            rng.random_range(0.01..0.08)
        } else {
            0.0
        });
    }
    (face, weights)
}

/// The true camera-to-world of frame `n` (25 fps): the head turns (yaw up to 25 deg, pitch
/// 15, roll 10, each scaled by `amplitude`) and shifts by a few cm in front of a camera 1 m
/// away; the camera, seen from the head, moves the opposite way.
fn true_c2w(n: usize, amplitude: f32) -> Mat4 {
    let t = n as f32 / 25.0;
    let wave = |period: f32, phase: f32| (std::f32::consts::TAU * t / period + phase).sin();
    let turn = Quat::from_rotation_y(amplitude * 25f32.to_radians() * wave(4.0, 0.0))
        * Quat::from_rotation_x(amplitude * 15f32.to_radians() * wave(3.1, 0.5))
        * Quat::from_rotation_z(amplitude * 10f32.to_radians() * wave(5.3, 1.0));
    let shift = Vec3::new(
        0.03 * wave(3.7, 0.2),
        0.02 * wave(4.9, 0.3),
        0.04 * wave(6.1, 0.4),
    );
    let head = Mat4::from_rotation_translation(turn, shift);
    head.inverse() * look_at(Vec3::new(0.0, 0.0, DISTANCE), Vec3::ZERO, Vec3::Y)
}

/// The kept frames of a clip: every 17th frame dropped.
fn kept_frames() -> Vec<usize> {
    kept_frames_of(N_FRAMES)
}

fn kept_frames_of(n_frames: usize) -> Vec<usize> {
    (0..n_frames).filter(|n| n % 17 != 5).collect()
}

/// Landmarks of `face` seen by `Camera::project` from `c2w`, plus `noise_px` Gaussian noise.
fn observe(
    face: &[Vec3],
    frames: &[usize],
    c2w: &[Mat4],
    focal: f32,
    noise_px: f32,
    seed: u64,
) -> Vec<FrameLandmarks> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    frames
        .iter()
        .zip(c2w)
        .map(|(&frame, c2w)| {
            let camera = Camera {
                intrinsics: intrinsics(focal),
                c2w: *c2w,
            };
            let points = face
                .iter()
                .map(|p| {
                    let (i, j, _) = camera
                        .project(*p)
                        .expect("the face is in front of the camera");
                    [
                        i + noise_px * gaussian(&mut rng),
                        j + noise_px * gaussian(&mut rng),
                    ]
                })
                .collect();
            FrameLandmarks { frame, points }
        })
        .collect()
}

fn rotation(m: &Mat4) -> DQuat {
    DQuat::from_mat3(&Mat3::from_mat4(*m).as_dmat3()).normalize()
}

/// Mean errors of a track against the truth.
#[derive(Debug)]
struct Errors {
    /// Angle of `R_est^T R_true` between the c2w rotations, degrees.
    rotation_deg: f64,
    /// Camera-centre distance, as a fraction of the true camera's distance to the origin.
    position: f64,
    /// Error of the camera's distance to the origin, as a fraction of it.
    distance: f64,
}

fn errors(est: &[Mat4], truth: &[Mat4]) -> Errors {
    let n = est.len() as f64;
    let mean = |f: &dyn Fn(&Mat4, &Mat4) -> f64| {
        est.iter().zip(truth).map(|(e, t)| f(e, t)).sum::<f64>() / n
    };
    let centre = |m: &Mat4| m.w_axis.truncate().as_dvec3();
    Errors {
        rotation_deg: mean(&|e, t| angle_between(rotation(e), rotation(t)).to_degrees()),
        position: mean(&|e, t| (centre(e) - centre(t)).length() / centre(t).length()),
        distance: mean(&|e, t| (centre(e).length() / centre(t).length() - 1.0).abs()),
    }
}

struct Clip {
    frames: Vec<FrameLandmarks>,
    truth: Vec<Mat4>,
}

fn clip(face: &[Vec3], amplitude: f32, noise_px: f32, seed: u64) -> Clip {
    clip_of(N_FRAMES, face, amplitude, noise_px, seed)
}

fn clip_of(n_frames: usize, face: &[Vec3], amplitude: f32, noise_px: f32, seed: u64) -> Clip {
    let kept = kept_frames_of(n_frames);
    let truth: Vec<Mat4> = kept.iter().map(|&n| true_c2w(n, amplitude)).collect();
    Clip {
        frames: observe(face, &kept, &truth, FOCAL, noise_px, seed),
        truth,
    }
}

fn solve(clip: &Clip, face: &[Vec3], weights: &[f32], focal: f32, cfg: &PoseConfig) -> CameraTrack {
    solve_track(&clip.frames, &[], face, weights, &intrinsics(focal), cfg).unwrap()
}

/// Everything but what is named: PnP, bundle and smoothing with the defaults.
fn with(change: impl FnOnce(&mut PoseConfig)) -> PoseConfig {
    let mut cfg = PoseConfig::default();
    change(&mut cfg);
    cfg
}
