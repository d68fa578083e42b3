//! Volume compositing along one ray (paper Eq. 3-4) and the light-segment colours the student
//! is distilled to (Eq. 5, segments as equal t-intervals of the ray's sampled span): an f64
//! reference written as plainly as the equations, and the f32 path that production code
//! mirrors (log-space transmittance, `expm1`, no division).
//!
//! With densities `sigma_k >= 0`, spacings `delta_k` and colours `c_k`:
//! `T_k = exp(-sum_{j<k} sigma_j delta_j)`, `w_k = T_k (1 - exp(-sigma_k delta_k))`,
//! `C = sum_k w_k c_k`, depth `= sum_k w_k t_k`, opacity `= sum_k w_k`.

/// What compositing one ray gives.
#[derive(Debug, Clone, PartialEq)]
pub struct Composite<F> {
    /// `w_k` per sample.
    pub weights: Vec<F>,
    /// `C`, the pixel colour.
    pub color: [F; 3],
    /// Expected ray parameter `sum w_k t_k`.
    pub depth: F,
    /// Accumulated opacity `sum w_k`, in [0, 1].
    pub opacity: F,
}

/// The segment, of `m`, that a sample at `t` belongs to on a ray sampled over `span =
/// (t0, t1)`: segments are `m` equal t-intervals of the span, `floor(m (t - t0) / (t1 - t0))`
/// clamped to `0..m`, so that their boundaries lie at the same depths whatever the sample
/// density (importance samples crowd where the density is, and a split by sample count
/// would follow them). With `n = m N'` stratified samples, one per equal bin, segment `i`
/// holds bins `i N'..(i + 1) N'`: the paper's split in order into groups of N/M.
pub fn segment_of(t: f64, span: (f64, f64), m: usize) -> usize {
    let (t0, t1) = span;
    let length = t1 - t0;
    if m <= 1 || length.is_nan() || length <= 0.0 {
        return 0;
    }
    let s = (m as f64 * (t - t0) / length).floor();
    if s.is_nan() || s < 0.0 {
        0
    } else {
        (s as usize).min(m - 1)
    }
}

/// The f64 reference of Eq. 3-4: transmittance as a running product of `exp(-sigma delta)`.
///
/// # Shapes
/// - `densities`, `deltas`, `t_vals`: `[n_samples]`; `colors`: `[n_samples]` of RGB
pub fn composite_f64(
    densities: &[f64],
    deltas: &[f64],
    t_vals: &[f64],
    colors: &[[f64; 3]],
) -> Composite<f64> {
    let mut transmittance = 1.0f64;
    let mut weights = Vec::with_capacity(densities.len());
    let (mut color, mut depth) = ([0.0f64; 3], 0.0f64);
    for k in 0..densities.len() {
        let sigma = densities[k].max(0.0);
        let alpha = 1.0 - (-sigma * deltas[k]).exp();
        let w = transmittance * alpha;
        transmittance *= (-sigma * deltas[k]).exp();
        weights.push(w);
        for c in 0..3 {
            color[c] += w * colors[k][c];
        }
        depth += w * t_vals[k];
    }
    Composite {
        opacity: weights.iter().sum(),
        weights,
        color,
        depth,
    }
}

/// The f64 reference of Eq. 5: segment `i`'s colour is `sum w_k c_k` over the samples in
/// its t-interval ([`segment_of`]), with the weights of the whole ray (transmittance from
/// the ray's start), so the segments sum to the pixel.
///
/// # Shapes
/// - `weights`, `t_vals`: `[n_samples]`; `colors`: `[n_samples]` of RGB; returns `[m]` of RGB
pub fn segment_colors_f64(
    weights: &[f64],
    colors: &[[f64; 3]],
    t_vals: &[f64],
    span: (f64, f64),
    m: usize,
) -> Vec<[f64; 3]> {
    let mut out = vec![[0.0; 3]; m.max(1)];
    for k in 0..weights.len() {
        let seg = &mut out[segment_of(t_vals[k], span, m)];
        for c in 0..3 {
            seg[c] += weights[k] * colors[k][c];
        }
    }
    out
}

/// The f32 compositing path: `sigma` clamped to >= 0 (NaN counts as 0), the optical depth
/// accumulated as a sum, `T_k = exp(-s_k)` and `1 - exp(-x)` through `expm1`. Finite for any
/// finite input, including `sigma = 1e30` and a last spacing of `1e10`.
///
/// # Shapes
/// - `densities`, `deltas`, `t_vals`: `[n_samples]`; `colors`: `[n_samples, 3]` flat
pub fn composite(
    densities: &[f32],
    deltas: &[f32],
    t_vals: &[f32],
    colors: &[f32],
) -> Composite<f32> {
    let n = densities.len();
    let mut weights = vec![0.0f32; n];
    composite_weights(densities, deltas, &mut weights);
    let (mut color, mut depth, mut opacity) = ([0.0f32; 3], 0.0f32, 0.0f32);
    for k in 0..n {
        let w = weights[k];
        for c in 0..3 {
            color[c] += w * colors[3 * k + c];
        }
        // A zero weight at an infinite t must not give NaN.
        if w > 0.0 {
            depth += w * t_vals[k];
        }
        opacity += w;
    }
    Composite {
        weights,
        color,
        depth,
        opacity: opacity.min(1.0),
    }
}

/// The f32 weights `w_k` of Eq. 3 into `weights` (see [`composite`]).
pub fn composite_weights(densities: &[f32], deltas: &[f32], weights: &mut [f32]) {
    let mut optical_depth = 0.0f32;
    for k in 0..densities.len() {
        let sigma = if densities[k] > 0.0 {
            densities[k]
        } else {
            0.0
        };
        let delta = if deltas[k] > 0.0 { deltas[k] } else { 0.0 };
        let tau = sigma * delta;
        let tau = if tau.is_nan() { 0.0 } else { tau };
        let transmittance = (-optical_depth).exp();
        let alpha = -(-tau).exp_m1();
        weights[k] = transmittance * alpha;
        optical_depth += tau;
    }
}

/// The f32 segment colours of Eq. 5 (see [`segment_colors_f64`]).
///
/// # Shapes
/// - `weights`, `t_vals`: `[n_samples]`; `colors`: `[n_samples, 3]` flat; returns `[m, 3]`
///   flat
pub fn segment_colors(
    weights: &[f32],
    colors: &[f32],
    t_vals: &[f32],
    span: (f32, f32),
    m: usize,
) -> Vec<f32> {
    let m = m.max(1);
    let span = (span.0 as f64, span.1 as f64);
    let mut out = vec![0.0f32; 3 * m];
    for k in 0..weights.len() {
        let i = segment_of(t_vals[k] as f64, span, m);
        for c in 0..3 {
            out[3 * i + c] += weights[k] * colors[3 * k + c];
        }
    }
    out
}
