//! The views the student learns from: the recorded training frames and, with R2L's pseudo
//! data, the teacher's views at poses beyond them with their recorded audio; each view's
//! hit pixels split into face, mouth and the rest.

use glam::{Mat4, Vec3};
use nldf_core::camera::{Camera, turn_about};
use nldf_core::dataset::Split;
use nldf_core::rays::head_rays;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::trainers::config::StudentTrainConfig;
use crate::trainers::data::TrainData;

/// The pixels of one training frame whose rays hit the head's bounds (the only ones the
/// student sees), split by where they lie.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameBeams {
    /// `(i, j)` of every hit pixel, in row-major order.
    pub pixels: Vec<(u32, u32)>,
    /// Indices into `pixels`: inside `face_rect`, outside it, inside the mouth region.
    pub face: Vec<u32>,
    pub other: Vec<u32>,
    pub mouth: Vec<u32>,
}

/// A view the student learns from: a training frame, or a pseudo view (R2L's pseudo data)
/// at a pose the recording lacks, with the recorded audio of a training frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    pub camera: Camera,
    /// The audio id whose code the view is rendered with: always a recorded frame's, since
    /// a mix of two frames' codes is a sound the teacher never heard (it cost 2.6 dB at the
    /// mouth when measured).
    pub aud_id: usize,
    /// The training frame the view comes from (its face and mouth regions are used).
    pub source: usize,
    /// Whether the view is a training frame, with a ground-truth image.
    pub recorded: bool,
}

/// The direction of a camera seen from `centre`, as yaw (about +y, from +z towards +x) and
/// pitch (towards +y), radians, and its distance.
pub fn view_angles(camera: &Camera, centre: Vec3) -> (f32, f32, f32) {
    let v = camera.origin() - centre;
    let r = v.length().max(1e-12);
    (v.x.atan2(v.z), (v.y / r).clamp(-1.0, 1.0).asin(), r)
}

/// The recorded range of the training cameras' yaw and pitch about the head's centre,
/// `([yaw_lo, yaw_hi], [pitch_lo, pitch_hi])`, radians.
pub fn recorded_range(data: &TrainData) -> ([f32; 2], [f32; 2]) {
    let ds = &data.dataset;
    let centre = data.bounds.centre();
    let mut yaw = [f32::INFINITY, f32::NEG_INFINITY];
    let mut pitch = yaw;
    for f in ds.frames(Split::Train) {
        let (y, p, _) = view_angles(&ds.camera(f), centre);
        yaw = [yaw[0].min(y), yaw[1].max(y)];
        pitch = [pitch[0].min(p), pitch[1].max(p)];
    }
    (yaw, pitch)
}

/// The training frames as views, then `cfg.pseudo_frames` pseudo views (with distillation
/// on). Each pseudo view takes a seeded training frame, its audio and its distance, and
/// turns its camera about the head's centre to a yaw and pitch drawn uniformly from the
/// recorded range widened `cfg.pose_range` times about its middle (the training data's own
/// units: 1 keeps to the recorded poses, 2 reaches twice as far out), then moves it closer
/// or farther by up to `cfg.pseudo_zoom` of its distance. Closer only while the camera
/// stays outside the head's bounds (the student's beams are anchored at the head, see
/// `nldf_core::beam::BeamAnchor`, so a closer camera asks nothing new of them).
pub fn training_views(data: &TrainData, cfg: &StudentTrainConfig) -> Vec<View> {
    let ds = &data.dataset;
    let frames = ds.frames(Split::Train);
    let mut views: Vec<View> = frames
        .iter()
        .enumerate()
        .map(|(fi, f)| View {
            camera: ds.camera(f),
            aud_id: f.aud_id,
            source: fi,
            recorded: true,
        })
        .collect();
    if !cfg.distill || frames.is_empty() {
        return views;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x5eed_5eed);
    let centre = data.bounds.centre();
    let (yaw, pitch) = recorded_range(data);
    let widen = |[lo, hi]: [f32; 2]| {
        let (mid, half) = (0.5 * (lo + hi), 0.5 * (hi - lo) * cfg.pose_range);
        (mid - half, mid + half)
    };
    let (yaw, pitch) = (widen(yaw), widen(pitch));
    let extent = data.bounds.hi - data.bounds.lo;
    let closest = 0.5 * extent.length();
    let draw = |rng: &mut ChaCha8Rng, (lo, hi): (f32, f32)| {
        if hi > lo {
            rng.random_range(lo..=hi)
        } else {
            lo
        }
    };
    for _ in 0..cfg.pseudo_frames {
        let source = rng.random_range(0..frames.len());
        let base = ds.camera(&frames[source]);
        let (y0, p0, _) = view_angles(&base, centre);
        let (y1, p1) = (draw(&mut rng, yaw), draw(&mut rng, pitch));
        let zoom = 1.0 + cfg.pseudo_zoom * rng.random_range(-1.0f32..=1.0);
        // Yaw about +y through the centre, then pitch in the vertical plane through the
        // centre and the camera: the turned camera sees the centre from (y1, p1) exactly.
        let turned = turn_about(centre, y1 - y0, 0.0) * base.c2w;
        let offset = turned.w_axis.truncate() - centre;
        let axis = offset.cross(Vec3::Y).normalize_or_zero();
        let tilt = if axis == Vec3::ZERO {
            Mat4::IDENTITY
        } else {
            Mat4::from_translation(centre)
                * Mat4::from_axis_angle(axis, p1 - p0)
                * Mat4::from_translation(-centre)
        };
        let mut c2w = tilt * turned;
        let offset = c2w.w_axis.truncate() - centre;
        let r = offset.length();
        // Closer only as far as `closest` allows, and never closer than recorded when the
        // recording itself is nearer than that.
        let r_new = (zoom * r).max(closest.min(r));
        c2w.w_axis = (centre + offset * (r_new / r.max(1e-12))).extend(1.0);
        views.push(View {
            camera: Camera {
                intrinsics: base.intrinsics,
                c2w,
            },
            aud_id: frames[source].aud_id,
            source,
            recorded: false,
        });
    }
    views
}

/// The hit pixels of every view. A view's face region is its source frame's; its mouth is
/// the source frame's mouth pixels for a recorded frame and, for a pseudo view given
/// `mouth_points` (each training frame's mouth pixels carried to the head's surface by the
/// teacher's depth, [`mouth_surface_points`]), those points projected into the view.
/// Without them a pseudo view takes its source frame's mouth pixels as they are, which
/// miss the mouth once the head turns.
pub fn frame_beams(
    data: &TrainData,
    views: &[View],
    mouth_points: Option<&[Vec<Vec3>]>,
) -> Vec<FrameBeams> {
    let ds = &data.dataset;
    let frames = ds.frames(Split::Train);
    let width = ds.intrinsics.width;
    views
        .par_iter()
        .map(|view| {
            let frame = &frames[view.source];
            let mouth: std::collections::HashSet<(u32, u32)> =
                match mouth_points.and_then(|m| m.get(view.source)) {
                    Some(points) if !view.recorded => projected_pixels(&view.camera, points),
                    _ => data
                        .mouth_pixels
                        .get(view.source)
                        .map(|m| m.iter().copied().collect())
                        .unwrap_or_default(),
                };
            let head = head_rays(&view.camera, &data.head_range());
            let mut fb = FrameBeams::default();
            for r in 0..head.pixels.len() {
                let (i, j) = head.pixel_ij(r, width);
                let k = fb.pixels.len() as u32;
                fb.pixels.push((i, j));
                if frame.face_rect.contains(i, j) {
                    fb.face.push(k);
                } else {
                    fb.other.push(k);
                }
                if mouth.contains(&(i, j)) {
                    fb.mouth.push(k);
                }
            }
            fb
        })
        .collect()
}

/// The pixels that `points` project to in `camera` (the nearest pixel of each), with the
/// holes between them closed: a pixel is added when at least three of its four
/// neighbours are hit.
pub fn projected_pixels(camera: &Camera, points: &[Vec3]) -> std::collections::HashSet<(u32, u32)> {
    let k = camera.intrinsics;
    let mut hit = std::collections::HashSet::new();
    for &p in points {
        if let Some((i, j, _)) = camera.project(p) {
            let (i, j) = (i.round(), j.round());
            if i >= 0.0 && j >= 0.0 && i < k.width as f32 && j < k.height as f32 {
                hit.insert((i as u32, j as u32));
            }
        }
    }
    let mut closed = hit.clone();
    for &(i, j) in &hit {
        for (di, dj) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
            let (x, y) = (i as i64 + di, j as i64 + dj);
            if x < 0 || y < 0 || x >= k.width as i64 || y >= k.height as i64 {
                continue;
            }
            let around = [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)]
                .iter()
                .filter(|(a, b)| {
                    let (u, v) = (x + a, y + b);
                    u >= 0 && v >= 0 && hit.contains(&(u as u32, v as u32))
                })
                .count();
            if around >= 3 {
                closed.insert((x as u32, y as u32));
            }
        }
    }
    closed
}

/// Each training frame's mouth pixels carried to the head's surface: the teacher renders
/// their rays with the frame's audio and keeps the point at its expected depth
/// ([`Teacher::surface_points`]). Pseudo views project them to find their mouth.
///
/// [`Teacher::surface_points`]: crate::networks::teacher::Teacher::surface_points
pub fn mouth_surface_points(
    teacher: &crate::trainers::teacher_trainer::TeacherModel,
    data: &TrainData,
) -> crate::Result<Vec<Vec<Vec3>>> {
    let ds = &data.dataset;
    let frames = ds.frames(Split::Train);
    let mut out = Vec::with_capacity(frames.len());
    for (fi, frame) in frames.iter().enumerate() {
        let pixels = data.mouth_pixels.get(fi).map(Vec::as_slice).unwrap_or(&[]);
        if pixels.is_empty() {
            out.push(Vec::new());
            continue;
        }
        let rays = nldf_core::rays::rays_for_pixels(&ds.camera(frame), pixels);
        let code = teacher.audio_codes(data, &[frame.aud_id])?;
        let points = teacher
            .teacher
            .surface_points(&rays, &code, &data.head_range())?;
        out.push(points.into_iter().flatten().collect());
    }
    Ok(out)
}

/// Keeps at most `n` hit pixels of each pseudo view (0 keeps all): its mouth pixels (up to
/// half of `n`), then pixels drawn without replacement, seeded by `seed` and the view. The
/// student draws only a few hundred rays from a view per step, so the teacher's time is
/// better spent on more poses than on every pixel of each (R2L renders whole images; here
/// the same teacher time covers `pixels / n` times as many poses). Recorded frames keep
/// every pixel: they carry the ground truth.
pub fn thin_pseudo_beams(views: &[View], beams: &mut [FrameBeams], n: usize, seed: u64) {
    thin_beams(views, beams, n, false, seed);
}

/// [`thin_pseudo_beams`] for the recorded frames (`recorded`) or the pseudo views.
pub fn thin_beams(views: &[View], beams: &mut [FrameBeams], n: usize, recorded: bool, seed: u64) {
    if n == 0 {
        return;
    }
    beams
        .par_iter_mut()
        .zip(views)
        .enumerate()
        .filter(|(_, (fb, view))| view.recorded == recorded && fb.pixels.len() > n)
        .for_each(|(vi, (fb, _))| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x7417_0b5e);
            rng.set_stream(vi as u64);
            let total = fb.pixels.len();
            let mut keep = vec![false; total];
            let mut mouth = fb.mouth.clone();
            mouth.shuffle(&mut rng);
            mouth.truncate(n / 2);
            mouth.iter().for_each(|&k| keep[k as usize] = true);
            let mut rest: Vec<u32> = (0..total as u32).filter(|&k| !keep[k as usize]).collect();
            rest.shuffle(&mut rng);
            rest.truncate(n - mouth.len());
            rest.iter().for_each(|&k| keep[k as usize] = true);
            // Old index -> new index, in the old (row-major) order.
            let mut new_index = vec![u32::MAX; total];
            let mut pixels = Vec::with_capacity(n);
            for (k, &p) in fb.pixels.iter().enumerate() {
                if keep[k] {
                    new_index[k] = pixels.len() as u32;
                    pixels.push(p);
                }
            }
            let remap = |list: &[u32]| -> Vec<u32> {
                list.iter()
                    .map(|&k| new_index[k as usize])
                    .filter(|&k| k != u32::MAX)
                    .collect()
            };
            *fb = FrameBeams {
                face: remap(&fb.face),
                other: remap(&fb.other),
                mouth: remap(&fb.mouth),
                pixels,
            };
        });
}

/// A fingerprint of the views (poses and audio) and of the pixels kept of each, stored
/// with the cached targets so that a cache made for other views is never used (FNV-1a
/// over their bits).
pub fn views_fingerprint(views: &[View], beams: &[FrameBeams]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |v: u64| {
        for b in v.to_le_bytes() {
            h = (h ^ b as u64).wrapping_mul(0x0100_0000_01b3);
        }
    };
    for v in views {
        v.camera
            .c2w
            .to_cols_array()
            .iter()
            .for_each(|x| eat(x.to_bits() as u64));
        eat(v.aud_id as u64);
    }
    for fb in beams {
        eat(fb.pixels.len() as u64);
        fb.pixels
            .iter()
            .for_each(|&(i, j)| eat(((i as u64) << 32) | j as u64));
    }
    format!("{h:016x}")
}
