//! Where a ray is sampled: only inside the head's bounds (a ray-box intersection within
//! [near, far]), stratified, with jitter when training. Produces flat f32 buffers; nothing
//! here knows the network.

use glam::Vec3;
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
    /// `[n_hit]`: the `(t0, t1)` each ray is sampled over, its entry into and exit from the
    /// bounds within `[near, far]` (the span Eq. 5's segments divide).
    pub spans: Vec<(f32, f32)>,
}

/// The samples of every ray that hits `bounds` (within `[near, far]`), in order: for each,
/// `place(o, d, (t0, t1), u, samples)` pushes its `n_samples` `t` values, spacings and
/// points, given its jitter `u` (`n_samples` draws from `rng`, in order, or ½ each without
/// it); the hit, span and view direction are pushed here.
pub fn sample_hits<R: Rng + ?Sized>(
    rays: &Rays,
    bounds: &Bounds,
    near: f32,
    far: f32,
    n_samples: usize,
    mut rng: Option<&mut R>,
    place: &mut PlaceSamples,
) -> RaySamples {
    let mut s = RaySamples {
        n_samples,
        ..RaySamples::default()
    };
    let mut u = vec![0.5f32; n_samples];
    for r in 0..rays.len() {
        let (o, d) = (rays.origin(r), rays.direction(r));
        let Some(span) = bounds.intersect(o, d, near, far) else {
            continue;
        };
        s.hit.push(r);
        s.spans.push(span);
        if let Some(g) = rng.as_deref_mut() {
            u.iter_mut().for_each(|v| *v = g.random::<f32>());
        }
        place(o, d, span, &u, &mut s);
        s.view_dirs
            .extend_from_slice(&(d / d.length().max(1e-12)).to_array());
    }
    s
}

/// Places one hit ray's samples for [`sample_hits`]: origin, direction, span, jitter.
pub type PlaceSamples<'a> = dyn FnMut(Vec3, Vec3, (f32, f32), &[f32], &mut RaySamples) + 'a;

/// Stratified samples inside the bounds: `n_samples` equal bins between entry and exit, one
/// sample per bin, at its centre or (with `rng`) uniformly inside it.
///
/// # Shapes
/// - see [`RaySamples`]; `n_hit` = rays that hit
pub fn sample_stratified<R: Rng + ?Sized>(
    rays: &Rays,
    bounds: &Bounds,
    near: f32,
    far: f32,
    n_samples: usize,
    rng: Option<&mut R>,
) -> RaySamples {
    sample_hits(
        rays,
        bounds,
        near,
        far,
        n_samples,
        rng,
        &mut |o, d, (t0, t1), u, s| {
            let norm = d.length();
            let bin = (t1 - t0) / n_samples as f32;
            let start = s.t_vals.len();
            for (k, &uk) in u.iter().enumerate() {
                s.t_vals.push(t0 + (k as f32 + uk) * bin);
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
        },
    )
}

/// Hierarchical sampling (NeRF): for each ray of `coarse`, `n_importance` more `t` values
/// drawn by inverse-transform sampling from the piecewise-constant density that the coarse
/// `weights` (plus a floor of 1e-5) put on the coarse samples' bins, merged with the coarse
/// samples and sorted; spacings and positions are recomputed. Bins run between the
/// midpoints of neighbouring coarse samples and out to the ray's entry and exit. Without
/// `rng` the draws are evenly spaced in probability (rendering).
///
/// # Shapes
/// - `weights`: `[n_hit, coarse.n_samples]`
/// - returns `n_samples = coarse.n_samples + n_importance` per ray, the same rays hit
pub fn sample_importance<R: Rng + ?Sized>(
    rays: &Rays,
    coarse: &RaySamples,
    weights: &[f32],
    n_importance: usize,
    mut rng: Option<&mut R>,
) -> RaySamples {
    let s = coarse.n_samples;
    let total = s + n_importance;
    let mut out = RaySamples {
        hit: coarse.hit.clone(),
        n_samples: total,
        view_dirs: coarse.view_dirs.clone(),
        spans: coarse.spans.clone(),
        ..RaySamples::default()
    };
    let mut edges = vec![0.0f32; s + 1];
    let mut cdf = vec![0.0f32; s + 1];
    let mut t_all = Vec::with_capacity(total);
    for (h, &r) in coarse.hit.iter().enumerate() {
        let (o, d) = (rays.origin(r), rays.direction(r));
        let t = &coarse.t_vals[h * s..(h + 1) * s];
        let (t0, t1) = coarse.spans[h];
        edges[0] = t0;
        for k in 1..s {
            edges[k] = 0.5 * (t[k - 1] + t[k]);
        }
        edges[s] = t1;
        cdf[0] = 0.0;
        for k in 0..s {
            let w = weights[h * s + k];
            let w = if w.is_finite() { w.max(0.0) } else { 0.0 };
            cdf[k + 1] = cdf[k] + w + 1e-5;
        }
        let norm = cdf[s];
        t_all.clear();
        t_all.extend_from_slice(t);
        for j in 0..n_importance {
            let jitter = match rng.as_deref_mut() {
                Some(g) => g.random::<f32>(),
                None => 0.5,
            };
            let u = (j as f32 + jitter) / n_importance as f32 * norm;
            // The bin whose cumulative range holds u.
            let k = cdf[1..].partition_point(|&c| c < u).min(s - 1);
            let span = (cdf[k + 1] - cdf[k]).max(1e-12);
            let frac = ((u - cdf[k]) / span).clamp(0.0, 1.0);
            t_all.push(edges[k] + frac * (edges[k + 1] - edges[k]));
        }
        t_all.sort_by(f32::total_cmp);
        let norm_d = d.length();
        for k in 0..total {
            let next = if k + 1 < total {
                t_all[k + 1]
            } else {
                t1.max(t_all[k])
            };
            out.t_vals.push(t_all[k]);
            out.deltas.push((next - t_all[k]).max(0.0) * norm_d);
            out.points.extend_from_slice(&(o + t_all[k] * d).to_array());
        }
    }
    out
}
