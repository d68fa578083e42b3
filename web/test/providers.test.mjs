// Which CPU providers onnxruntime-web offers the page (web/README.md): `wasm` runs the shipped
// frame graph; `xnnpack` is not registered in this release. When an update registers it,
// this test fails, and the page's choice of provider is to be measured again.
// node --test web/test/providers.test.mjs
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { readFileSync } from 'node:fs';
import * as ort from 'onnxruntime-web';

const frameGraph = readFileSync(new URL('../../models/demo/frame.onnx', import.meta.url));
ort.env.wasm.numThreads = 1;

test('the page runs the shipped frame graph on the wasm provider', async () => {
  const session = await ort.InferenceSession.create(frameGraph, { executionProviders: ['wasm'] });
  assert.deepEqual(session.inputNames, ['audio', 'pose', 'keep']);
});

test('onnxruntime-web offers no xnnpack provider', async () => {
  await assert.rejects(
    ort.InferenceSession.create(frameGraph, { executionProviders: ['xnnpack'] }),
    /xnnpack\] backend not found/,
  );
});
