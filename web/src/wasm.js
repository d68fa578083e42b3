// What the browser's WebAssembly supports, found by validating tiny modules (as
// onnxruntime-web checks before it loads its SIMD build).

// A module whose one function returns a v128 (i32.const 0, i8x16.splat, i8x16.popcnt):
// it validates only where WebAssembly has fixed-width SIMD.
export const SIMD_PROBE = new Uint8Array([
  0, 97, 115, 109, 1, 0, 0, 0, 1, 5, 1, 96, 0, 1, 123, 3, 2, 1, 0, 10, 10, 1, 8, 0, 65, 0, 253, 15, 253, 98, 11,
]);

// Whether this engine's WebAssembly has fixed-width SIMD.
export function wasmSimd(wasm = globalThis.WebAssembly) {
  try {
    return !!wasm?.validate(SIMD_PROBE);
  } catch {
    return false;
  }
}
