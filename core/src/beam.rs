//! The student's input: a whole camera ray ("light beam", paper section 3.2, after R2L)
//! sampled at K points between near and far, concatenated and positionally encoded.
//!
//! A beam may be anchored ([`BeamAnchor`]): the ray is first re-expressed by the line it
//! lies on, so that a camera closer to or farther from the head sees the same beam along
//! the same line. Without an anchor the points sit at fixed distances from the camera and
//! the head slides through them as the camera moves.

use glam::{DVec3, Vec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::encoding::{encode_positions, encoded_len};
use crate::rays::Rays;

/// Where beams are anchored: every ray is moved along its line so that its origin lies
/// `distance` before the line's closest approach to `centre`, with a unit direction. A
/// ray's beam then depends on its line alone, not on where the camera stands on it.
///
/// With `u = d / |d|` and `s = (centre - o) . u` (the closest approach's distance along
/// the ray), the anchored ray is `o' = o + (s - distance) u`, direction `u`. For a camera
/// at `distance` from the head looking at its centre, the central ray is unchanged.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BeamAnchor {
    /// The head's centre (its bounds' centre), world space.
    pub centre: [f32; 3],
    /// The recorded cameras' mean distance to the centre along their viewing axes.
    pub distance: f32,
}

impl BeamAnchor {
    /// The anchor of cameras whose camera-to-world matrices are `c2ws` (OpenGL axes: the
    /// camera looks along its -z column), around `centre`: the mean depth of the centre
    /// along their viewing axes. `None` without cameras or with a non-finite mean.
    pub fn of_cameras(centre: Vec3, c2ws: &[glam::Mat4]) -> Option<BeamAnchor> {
        if c2ws.is_empty() {
            return None;
        }
        let sum: f64 = c2ws
            .iter()
            .map(|m| {
                let forward = -m.z_axis.truncate().normalize_or_zero();
                f64::from((centre - m.w_axis.truncate()).dot(forward))
            })
            .sum();
        let distance = (sum / c2ws.len() as f64) as f32;
        distance.is_finite().then_some(BeamAnchor {
            centre: centre.to_array(),
            distance,
        })
    }

    /// The anchored origin and unit direction of the ray `(o, d)`, computed in f64 and
    /// rounded once (as the exported graph computes them). A zero direction leaves the ray
    /// as it is; an origin too far to hold in f32 becomes infinite, which the beam's clamp
    /// then bounds.
    pub fn apply(&self, o: Vec3, d: Vec3) -> (Vec3, Vec3) {
        let (o64, d64) = (o.as_dvec3(), d.as_dvec3());
        let len = d64.dot(d64).sqrt().max(f64::from(MIN_DIRECTION_LENGTH));
        let u = d64 / len;
        let s = (DVec3::from_array(self.centre.map(f64::from)) - o64).dot(u);
        let origin = o64 + (s - f64::from(self.distance)) * u;
        (origin.as_vec3(), u.as_vec3())
    }
}

/// The ray `(o, d)` as a beam samples it: anchored by `anchor` ([`BeamAnchor::apply`]) when
/// there is one, else as it is. The student's beams and the teacher's targets for them go
/// through here, so that both see the same rays.
pub fn beam_ray(anchor: Option<&BeamAnchor>, o: Vec3, d: Vec3) -> (Vec3, Vec3) {
    match anchor {
        Some(anchor) => anchor.apply(o, d),
        None => (o, d),
    }
}

/// Lengths of a ray direction below this count as this: a zero direction gives a zero
/// unit direction instead of NaN.
pub const MIN_DIRECTION_LENGTH: f32 = 1e-30;

/// How a beam is sampled and encoded.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BeamSpec {
    /// Points per beam, K (R2L and the paper: 16).
    pub n_points: usize,
    /// Positional-encoding frequencies, L (NeRF and the paper: 10).
    pub n_freqs: usize,
    /// Where rays are anchored before they are sampled ([`BeamAnchor`]); none in models
    /// made before anchoring existed, whose points keep fixed distances from the camera.
    pub anchor: Option<BeamAnchor>,
}

impl Default for BeamSpec {
    fn default() -> Self {
        BeamSpec {
            n_points: 16,
            n_freqs: 10,
            anchor: None,
        }
    }
}

impl BeamSpec {
    /// Length of one encoded beam: `3 K (1 + 2 L)` (1008 for the defaults).
    pub fn encoded_len(&self) -> usize {
        encoded_len(3 * self.n_points, self.n_freqs)
    }

    /// The `t` of point `k`: `near + (far - near) k / (K - 1)`, shifted by `jitter` in units
    /// of the spacing and kept inside [near, far].
    pub fn t_value(&self, k: usize, near: f32, far: f32, jitter: f32) -> f32 {
        let spacing = if self.n_points > 1 {
            (far - near) / (self.n_points - 1) as f32
        } else {
            0.0
        };
        (near + spacing * (k as f32 + jitter)).clamp(near.min(far), far.max(near))
    }
}

/// Encodes every ray of `rays` as a beam: points `x_k = o + t_k d` for k in 0..K (see
/// [`BeamSpec::t_value`]; `o` and `d` anchored first when the spec has a [`BeamAnchor`]),
/// concatenated as `[x_0, y_0, z_0, x_1, ...]` (3K values) and
/// positionally encoded. With `jitter`, each point moves by a uniform offset in
/// [-0.5, 0.5) of the spacing (training); without, points are evenly spaced (rendering).
///
/// # Shapes
/// - `rays`: `n_rays` rays
/// - `out`: `[n_rays, 3 K (1 + 2 L)]` row-major
///
/// # Panics
/// If `out` has the wrong length (a caller bug).
pub fn encode_beams(
    rays: &Rays,
    near: f32,
    far: f32,
    spec: &BeamSpec,
    mut jitter: Option<&mut dyn rand::RngCore>,
    out: &mut [f32],
) {
    let width = spec.encoded_len();
    assert_eq!(out.len(), rays.len() * width, "beam buffer length");
    let mut points = vec![0.0f32; 3 * spec.n_points];
    for (r, row) in out.chunks_exact_mut(width).enumerate() {
        let (o, d) = beam_ray(spec.anchor.as_ref(), rays.origin(r), rays.direction(r));
        for k in 0..spec.n_points {
            let u = match jitter.as_deref_mut() {
                Some(rng) => rng.random::<f32>() - 0.5,
                None => 0.0,
            };
            let p = o + spec.t_value(k, near, far, u) * d;
            points[3 * k..3 * k + 3].copy_from_slice(&p.to_array());
        }
        encode_positions(&points, spec.n_freqs, row);
    }
}

/// Rays per task of [`encode_beams_parallel`].
const ENCODE_CHUNK: usize = 256;

/// Encodes beams in parallel; with `jitter_seed`, chunk `c` of rays jitters its points
/// with a generator seeded by `(jitter_seed, c)`, so the result does not depend on the
/// thread count.
///
/// # Shapes
/// - returns `[rays.len(), spec.encoded_len()]` flat
pub fn encode_beams_parallel(
    rays: &Rays,
    near: f32,
    far: f32,
    spec: &BeamSpec,
    jitter_seed: Option<u64>,
) -> Vec<f32> {
    let width = spec.encoded_len();
    let mut out = vec![0.0f32; rays.len() * width];
    out.par_chunks_mut(ENCODE_CHUNK * width)
        .enumerate()
        .for_each(|(c, chunk)| {
            let lo = c * ENCODE_CHUNK;
            let n = chunk.len() / width.max(1);
            let part = rays.slice(lo..lo + n);
            match jitter_seed {
                Some(seed) => {
                    let mut rng = ChaCha8Rng::seed_from_u64(seed);
                    rng.set_stream(c as u64 + 1);
                    encode_beams(&part, near, far, spec, Some(&mut rng), chunk);
                }
                None => encode_beams(&part, near, far, spec, None, chunk),
            }
        });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const ANCHOR: BeamAnchor = BeamAnchor {
        centre: [0.1, -0.2, 0.05],
        distance: 1.0,
    };

    fn encode(rays: &Rays, spec: &BeamSpec) -> Vec<f32> {
        let mut out = vec![0.0f32; rays.len() * spec.encoded_len()];
        encode_beams(rays, 0.8, 1.4, spec, None, &mut out);
        out
    }

    fn max_diff(a: &[f32], b: &[f32]) -> f32 {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f32::max)
    }

    #[test]
    fn an_anchored_beam_depends_on_the_line_alone() {
        let centre = Vec3::from_array(ANCHOR.centre);
        // One line through the head, seen from three distances, with directions of other
        // lengths (as pixels off the principal point have).
        let dir = Vec3::new(0.2, 0.1, -1.0).normalize();
        let through = centre + Vec3::new(0.03, 0.02, 0.0);
        let mut rays = Rays::default();
        for (dist, scale) in [(1.0, 1.0), (0.85, 1.07), (1.3, 0.93)] {
            rays.push(through - dist * dir, scale * dir);
        }
        let anchored = BeamSpec {
            n_points: 8,
            n_freqs: 6,
            anchor: Some(ANCHOR),
        };
        let plain = BeamSpec {
            anchor: None,
            ..anchored
        };
        let w = anchored.encoded_len();
        let a = encode(&rays, &anchored);
        let p = encode(&rays, &plain);
        for r in 1..3 {
            let (row, first) = (&a[r * w..(r + 1) * w], &a[..w]);
            assert!(max_diff(row, first) < 1e-3, "{}", max_diff(row, first));
            // Without the anchor the points slide along the line with the camera.
            assert!(max_diff(&p[r * w..(r + 1) * w], &p[..w]) > 0.1);
        }
    }

    #[test]
    fn anchoring_leaves_a_camera_at_the_anchor_distance_alone() {
        let centre = Vec3::from_array(ANCHOR.centre);
        let o = centre + Vec3::new(0.0, 0.0, ANCHOR.distance);
        let (o2, d2) = ANCHOR.apply(o, Vec3::new(0.0, 0.0, -1.0));
        assert!((o2 - o).length() < 1e-6, "{o2} {o}");
        assert!((d2 - Vec3::new(0.0, 0.0, -1.0)).length() < 1e-7);
    }

    #[test]
    fn anchored_beams_stay_finite_for_zero_directions_and_huge_coordinates() {
        let mut rays = Rays::default();
        rays.push(Vec3::new(0.3, 0.1, 1.0), Vec3::ZERO);
        rays.push(Vec3::splat(3e38), Vec3::new(-3e38, 1e-30, 3e38));
        rays.push(Vec3::new(-3e38, 0.0, 1.0), Vec3::new(1e-38, 0.0, -1e-38));
        let spec = BeamSpec {
            n_points: 4,
            n_freqs: 4,
            anchor: Some(ANCHOR),
        };
        let out = encode(&rays, &spec);
        assert!(out.iter().all(|v| v.is_finite()), "{out:?}");
        let (o, d) = ANCHOR.apply(Vec3::new(0.3, 0.1, 1.0), Vec3::ZERO);
        assert_eq!((o, d), (Vec3::new(0.3, 0.1, 1.0), Vec3::ZERO));
    }

    #[test]
    fn the_anchor_of_cameras_is_their_mean_depth_of_the_centre() {
        let centre = Vec3::new(0.0, 0.1, 0.0);
        let at = |z: f32| glam::Mat4::from_translation(Vec3::new(0.0, 0.1, z));
        let a = BeamAnchor::of_cameras(centre, &[at(1.0), at(1.2)]).unwrap();
        assert!((a.distance - 1.1).abs() < 1e-6, "{}", a.distance);
        assert_eq!(a.centre, centre.to_array());
        assert!(BeamAnchor::of_cameras(centre, &[]).is_none());
    }
}
