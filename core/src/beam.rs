//! The student's input: a whole camera ray ("light beam", paper section 3.2, after R2L)
//! sampled at K points between near and far, concatenated and positionally encoded.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::encoding::{encode_positions, encoded_len};
use crate::rays::Rays;

/// How a beam is sampled and encoded.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BeamSpec {
    /// Points per beam, K (R2L and the paper: 16).
    pub n_points: usize,
    /// Positional-encoding frequencies, L (NeRF and the paper: 10).
    pub n_freqs: usize,
}

impl Default for BeamSpec {
    fn default() -> Self {
        BeamSpec {
            n_points: 16,
            n_freqs: 10,
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
/// [`BeamSpec::t_value`]), concatenated as `[x_0, y_0, z_0, x_1, ...]` (3K values) and
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
        let o = rays.origin(r);
        let d = rays.direction(r);
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
