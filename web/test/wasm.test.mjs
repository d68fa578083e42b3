// The page's WebAssembly feature detection (src/wasm.js) in node: found, not assumed.
// node --test web/test/wasm.test.mjs
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { SIMD_PROBE, wasmSimd } from '../src/wasm.js';

test('SIMD is detected by validating a module that needs it', () => {
  // Node's V8 has had fixed-width SIMD since node 16.
  assert.equal(wasmSimd(), true);
  assert.equal(WebAssembly.validate(SIMD_PROBE), true);
  // The probe needs SIMD: its v128 result type (0x7b) as i32 (0x7f) no longer validates,
  // its body still returning a v128.
  const i32 = SIMD_PROBE.slice();
  i32[i32.indexOf(123)] = 127;
  assert.equal(WebAssembly.validate(i32), false);
});

test('an engine without SIMD, or without WebAssembly, is reported as such', () => {
  // An engine that rejects every module using a SIMD opcode (prefix 0xfd) or type (0x7b).
  const noSimd = {
    validate: (bytes) => !bytes.includes(0xfd) && !bytes.includes(0x7b) && WebAssembly.validate(bytes),
  };
  assert.equal(wasmSimd(noSimd), false);
  assert.equal(wasmSimd(undefined), true, 'undefined means the global WebAssembly');
  assert.equal(wasmSimd(null), false);
  assert.equal(wasmSimd({ validate: () => { throw new Error('no'); } }), false);
});
