//! Where a ray is sampled: only inside the head's bounds (a ray-box intersection within
//! [near, far]), stratified, with jitter when training. Produces flat f32 buffers; nothing
//! here knows the network.

use nldf_core::bounds::Bounds;
use nldf_core::rays::Rays;
use rand::Rng;

/// Samples along the rays that hit the bounds.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RaySamples {
    /// Which input rays hit the bounds, in order; only these are sampled.
    pub hit: Vec<usize>,
    /// Samples per ray.
    pub n_samples: usize,
    /// `[n_hit, n_samples]`: `t` of each sample.
    pub t_vals: Vec<f32>,
    /// `[n_hit, n_samples]`: distance from each sample to the next (the last to the exit),
    /// in world units (`dt |d|`).
    pub deltas: Vec<f32>,
    /// `[n_hit, n_samples, 3]`: sample positions `o + t d`.
    pub points: Vec<f32>,
    /// `[n_hit, 3]`: unit view directions.
    pub view_dirs: Vec<f32>,
}

/// Stratified samples inside the bounds: `n_samples` equal bins between entry and exit, one
/// sample per bin, at its centre or (with `rng`) uniformly inside it.
///
/// # Shapes
/// - see [`RaySamples`]; `n_hit` = rays that hit
pub fn sample_stratified(
    rays: &Rays,
    bounds: &Bounds,
    near: f32,
    far: f32,
    n_samples: usize,
    mut rng: Option<&mut dyn rand::RngCore>,
) -> RaySamples {
    let mut s = RaySamples {
        n_samples,
        ..RaySamples::default()
    };
    for r in 0..rays.len() {
        let (o, d) = (rays.origin(r), rays.direction(r));
        let Some((t0, t1)) = bounds.intersect(o, d, near, far) else {
            continue;
        };
        s.hit.push(r);
        let norm = d.length();
        let bin = (t1 - t0) / n_samples as f32;
        let start = s.t_vals.len();
        for k in 0..n_samples {
            let u = match rng.as_deref_mut() {
                Some(g) => g.random::<f32>(),
                None => 0.5,
            };
            s.t_vals.push(t0 + (k as f32 + u) * bin);
        }
        for k in 0..n_samples {
            let t = s.t_vals[start + k];
            let next = if k + 1 < n_samples {
                s.t_vals[start + k + 1]
            } else {
                t1
            };
            s.deltas.push((next - t).max(0.0) * norm);
            s.points.extend_from_slice(&(o + t * d).to_array());
        }
        s.view_dirs
            .extend_from_slice(&(d / norm.max(1e-12)).to_array());
    }
    s
}
