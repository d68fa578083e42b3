//! NeRF's positional encoding, written as NeRF's embedder writes it:
//! `[x, sin(2^0 x), cos(2^0 x), sin(2^1 x), cos(2^1 x), ..., sin(2^(L-1) x), cos(2^(L-1) x)]`,
//! each block holding all input values in order. Only the lowest octave calls `sin` and
//! `cos`; the others follow by the double-angle identities ([`double_angle`]), in training
//! and in the exported graph alike.

/// Coordinates are clamped to `[-MAX_COORD, MAX_COORD]` before encoding, so that
/// `2^(L-1) x` stays finite and far from where f32 `sin` loses all meaning; every backend
/// (candle, the ONNX graph) applies the same clamp.
pub const MAX_COORD: f32 = 1.0e4;

/// Width of the encoding of `n_values` values with `n_freqs` frequencies: `n (1 + 2 L)`.
pub fn encoded_len(n_values: usize, n_freqs: usize) -> usize {
    n_values * (1 + 2 * n_freqs)
}

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
    let clamped: &[f32] = head;
    for l in 0..n_freqs {
        let (done, block) = rest.split_at_mut(2 * n * l);
        let (sins, coss) = block[..2 * n].split_at_mut(n);
        if l == 0 {
            for ((s, c), &x) in sins.iter_mut().zip(coss.iter_mut()).zip(clamped) {
                (*s, *c) = x.sin_cos();
            }
            continue;
        }
        let prev = &done[2 * n * (l - 1)..];
        let (prev_s, prev_c) = prev.split_at(n);
        for (i, (s, c)) in sins.iter_mut().zip(coss.iter_mut()).enumerate() {
            (*s, *c) = double_angle(prev_s[i], prev_c[i]);
        }
    }
}

/// `(sin 2a, cos 2a)` from `(sin a, cos a)`: `2 sin a cos a` and
/// `(cos a - sin a)(cos a + sin a)`, in exactly these f32 operations (the ONNX export
/// writes the same ones).
///
/// The positional encoding takes `sin` and `cos` once, at the lowest frequency, and climbs
/// the octaves with this identity: 2 transcendental calls per value instead of `2 L`. The
/// rounding error doubles with each octave, like the error of the f32 argument `2^l x` it
/// replaces, so the top octave of `L = 10` stays within about `2^10` ulp of the exact value.
#[inline]
pub fn double_angle(s: f32, c: f32) -> (f32, f32) {
    let p = s * c;
    (p + p, (c - s) * (c + s))
}

/// The encoding of `values` as a new vector (see [`encode_positions`]).
pub fn positional_encoding(values: &[f32], n_freqs: usize) -> Vec<f32> {
    let mut out = vec![0.0; encoded_len(values.len(), n_freqs)];
    encode_positions(values, n_freqs, &mut out);
    out
}
