//! NeRF's positional encoding, written as NeRF's embedder writes it:
//! `[x, sin(2^0 x), cos(2^0 x), sin(2^1 x), cos(2^1 x), ..., sin(2^(L-1) x), cos(2^(L-1) x)]`,
//! each block holding all input values in order.
//!
//! Each value's sine and cosine are taken once, in f64, at the lowest octave; the others
//! follow by the double-angle identities ([`double_angle`]), also in f64, and each result
//! is rounded to f32 once. That costs 2 transcendental calls per value instead of `2 L`,
//! and the result is the f32 rounding of the exact `sin(2^l x)`: the double-angle climb
//! doubles its rounding error at each octave, which f64's 2^-53 absorbs (at most about
//! `2^L 2^-53`, below 1e-13 for `L = 10`), where in f32 it reached about 5e-5 at the top
//! octave. The exported graph computes the same operations in double precision.

/// Coordinates are clamped to `[-MAX_COORD, MAX_COORD]` before encoding, so that
/// `2^(L-1) x` stays far from where a sine means nothing; every backend (candle, the ONNX
/// graph) applies the same clamp.
pub const MAX_COORD: f32 = 1.0e4;

/// The largest difference between an encoded value and the f32 rounding of the exact
/// `sin(2^l x)` / `cos(2^l x)` (f64 reference), for every `|x| <= MAX_COORD` and `L <= 16`:
/// half an f32 ulp at 1 plus the f64 climb's error. The ONNX contract states the same bound.
pub const MAX_ENCODING_ERROR: f64 = 1.0e-7;

/// Width of the encoding of `n_values` values with `n_freqs` frequencies: `n (1 + 2 L)`.
pub fn encoded_len(n_values: usize, n_freqs: usize) -> usize {
    n_values * (1 + 2 * n_freqs)
}

/// Positional encoding of `n` 3-vectors (the teacher's sample points and view directions),
/// in parallel over blocks of 256 vectors.
///
/// # Shapes
/// - `values`: `[n, 3]` flat; returns `[n, 3 (1 + 2 n_freqs)]` flat
pub fn encode_vectors(values: &[f32], n_freqs: usize) -> Vec<f32> {
    use rayon::prelude::*;
    let width = encoded_len(3, n_freqs);
    let n = values.len() / 3;
    let mut out = vec![0.0f32; n * width];
    out.par_chunks_mut(width * 256)
        .zip(values.par_chunks(3 * 256))
        .for_each(|(o, v)| {
            for (o, v) in o.chunks_mut(width).zip(v.chunks(3)) {
                encode_positions(v, n_freqs, o);
            }
        });
    out
}

/// Values encoded per pass of [`encode_positions`] (a beam holds 48).
const CHUNK: usize = 64;

/// Writes the positional encoding of `values` with `n_freqs` frequencies into `out`.
///
/// # Shapes
/// - `values`: `[n]`
/// - `out`: `[n (1 + 2 n_freqs)]`, laid out `[x | sin(2^0 x) | cos(2^0 x) | ...]`
///
/// # Panics
/// If `out` has the wrong length (a caller bug).
pub fn encode_positions(values: &[f32], n_freqs: usize, out: &mut [f32]) {
    let n = values.len();
    assert_eq!(
        out.len(),
        encoded_len(n, n_freqs),
        "positional encoding buffer length"
    );
    let (head, rest) = out.split_at_mut(n);
    for (o, &v) in head.iter_mut().zip(values) {
        *o = v.clamp(-MAX_COORD, MAX_COORD);
    }
    let (mut s, mut c) = ([0.0f64; CHUNK], [0.0f64; CHUNK]);
    for lo in (0..n).step_by(CHUNK) {
        let hi = (lo + CHUNK).min(n);
        let len = hi - lo;
        for i in 0..len {
            (s[i], c[i]) = (head[lo + i] as f64).sin_cos();
        }
        for l in 0..n_freqs {
            let block = &mut rest[2 * n * l..2 * n * (l + 1)];
            let (sins, coss) = block.split_at_mut(n);
            for i in 0..len {
                sins[lo + i] = s[i] as f32;
                coss[lo + i] = c[i] as f32;
                (s[i], c[i]) = double_angle(s[i], c[i]);
            }
        }
    }
}

/// `(sin 2a, cos 2a)` from `(sin a, cos a)`: `2 sin a cos a` and
/// `(cos a - sin a)(cos a + sin a)`, in exactly these f64 operations (the ONNX export writes
/// the same ones).
#[inline]
pub fn double_angle(s: f64, c: f64) -> (f64, f64) {
    let p = s * c;
    (p + p, (c - s) * (c + s))
}

/// The encoding of `values` as a new vector (see [`encode_positions`]).
pub fn positional_encoding(values: &[f32], n_freqs: usize) -> Vec<f32> {
    let mut out = vec![0.0; encoded_len(values.len(), n_freqs)];
    encode_positions(values, n_freqs, &mut out);
    out
}
