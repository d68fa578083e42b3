// The page's live chunks (src/model.js) in node, no browser: where the microphone's newest
// sample goes in a frame graph's chunk. nldf's FrameAudio::read_end (core/src/frame_audio.rs)
// is the reference; the layout is nldf's default at 25 fps with an 8-frame neighbourhood.
// node --test web/test/model.test.mjs
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { liveChunk, readEnd } from '../src/model.js';
import { Ring } from '../src/audio.js';

// FrameAudio::new(&FeatureConfig::default(), 25.0, 8).
const LAYOUT = { samples: 9680, offset: -5320, samples_per_frame: 640, hop: 320, win: 400, window: 16 };

test('the graph reads to its window end without attention, to the chunk end with it', () => {
  // The frame's instant is chunk sample 5320; the full window reads 152.5 ms past it.
  assert.equal(readEnd(LAYOUT, false, null), 5320 + 2440);
  // A short-lookahead student reading 5 rows past the centre: 92.5 ms.
  assert.equal(readEnd(LAYOUT, false, 5), 5320 + 1480);
  assert.equal(readEnd(LAYOUT, false, 1), 5320 + 200);
  assert.equal(readEnd(LAYOUT, true, null), 9680);
});

test('the newest samples end at the read end, NaN after and in front while few', () => {
  const layout = { ...LAYOUT, readEnd: readEnd(LAYOUT, false, 5) };
  const ring = new Ring(20000);
  ring.push(Float32Array.from({ length: 10000 }, (_, i) => i));
  const chunk = liveChunk(layout, ring);
  assert.equal(chunk.length, 9680);
  assert.equal(chunk[6799], 9999);
  assert.equal(chunk[0], 9999 - 6799);
  assert.ok(chunk.slice(6800).every(Number.isNaN));
  const few = new Ring(20000);
  few.push(Float32Array.from({ length: 100 }, (_, i) => i));
  const short = liveChunk(layout, few);
  assert.ok(short.slice(0, 6700).every(Number.isNaN));
  assert.equal(short[6700], 0);
  assert.equal(short[6799], 99);
  // Without a read end, the chunk's own end.
  const whole = liveChunk(LAYOUT, ring);
  assert.equal(whole[9679], 9999);
});
