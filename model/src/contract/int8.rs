/// The largest magnitude of a quantized weight in an int8 graph: 7 bits, not 8.
/// `MatMulInteger` multiplies uint8 activations (up to 255) by these weights. On x86 CPUs
/// without VNNI, onnxruntime's u8 x s8 kernel (AVX2 `vpmaddubsw`) adds each pair of
/// neighbouring products in a saturating 16-bit lane: with 8-bit weights a pair reaches
/// 2 x 255 x 127 = 64770 and clips at 32767. With 7-bit weights it reaches at most
/// 2 x 255 x [`INT8_WEIGHT_MAX`] = 32130 < 32767, so no pair can saturate on any CPU
/// (onnxruntime's `reduce_range`).
pub const INT8_WEIGHT_MAX: i8 = 63;

/// The largest sum of two neighbouring u8 x s8 products that an int8 graph's weights allow.
pub const fn int8_pair_sum_max() -> i32 {
    2 * 255 * INT8_WEIGHT_MAX as i32
}
