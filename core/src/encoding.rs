//! NeRF's positional encoding, written as NeRF's embedder writes it:
//! `[x, sin(2^0 x), cos(2^0 x), sin(2^1 x), cos(2^1 x), ..., sin(2^(L-1) x), cos(2^(L-1) x)]`,
//! each block holding all input values in order.

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
    for (l, block) in rest.chunks_exact_mut(2 * n).enumerate() {
        let freq = (1u64 << l) as f32;
        let (sins, coss) = block.split_at_mut(n);
        for ((s, c), &x) in sins.iter_mut().zip(coss.iter_mut()).zip(clamped) {
            let (sv, cv) = (x * freq).sin_cos();
            *s = sv;
            *c = cv;
        }
    }
}

/// The encoding of `values` as a new vector (see [`encode_positions`]).
pub fn positional_encoding(values: &[f32], n_freqs: usize) -> Vec<f32> {
    let mut out = vec![0.0; encoded_len(values.len(), n_freqs)];
    encode_positions(values, n_freqs, &mut out);
    out
}
