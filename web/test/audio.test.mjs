// The page's WAV reader (src/audio.js) in node, no browser: float WAVs with NaN or infinite
// samples are refused in nldf's words (`decode_wav`, core/src/audio.rs: "sample N is not
// finite", N the frame), finite ones read bit for bit as nldf reads them.
// node --test web/test/audio.test.mjs
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { decodeTo16k, parseWav } from '../src/audio.js';

// A WAV of interleaved `values`: 32-bit float (format 3, or 0xfffe with the float subformat
// when `extensible`) or 16-bit PCM (`values` are then integers).
function wav(values, { channels = 1, rate = 16000, float = true, extensible = false } = {}) {
  const width = float ? 4 : 2;
  const fmtSize = extensible ? 40 : 16;
  const dataSize = values.length * width;
  const buf = new DataView(new ArrayBuffer(20 + fmtSize + 8 + dataSize));
  const tag = (at, s) => [...s].forEach((c, i) => buf.setUint8(at + i, c.charCodeAt(0)));
  tag(0, 'RIFF');
  buf.setUint32(4, 12 + fmtSize + 8 + dataSize, true);
  tag(8, 'WAVE');
  tag(12, 'fmt ');
  buf.setUint32(16, fmtSize, true);
  const format = float ? 3 : 1;
  buf.setUint16(20, extensible ? 0xfffe : format, true);
  buf.setUint16(22, channels, true);
  buf.setUint32(24, rate, true);
  buf.setUint32(28, rate * channels * width, true);
  buf.setUint16(32, channels * width, true);
  buf.setUint16(34, width * 8, true);
  if (extensible) {
    buf.setUint16(36, 22, true);
    buf.setUint16(38, width * 8, true);
    buf.setUint32(40, 0, true);
    buf.setUint16(44, format, true);
  }
  const data = 20 + fmtSize;
  tag(data, 'data');
  buf.setUint32(data + 4, dataSize, true);
  values.forEach((v, i) => {
    const at = data + 8 + i * width;
    if (float) buf.setFloat32(at, v, true);
    else buf.setInt16(at, v, true);
  });
  return new Uint8Array(buf.buffer);
}

test('a NaN or infinite sample is refused, naming the file and the frame', () => {
  const cases = [
    ['NaN, mono', wav([0.1, 0.2, -0.3, NaN, 0.5]), 3],
    ['+Inf, stereo, second channel', wav([0, 0, 0.1, 0.1, 0.2, Infinity], { channels: 2 }), 2],
    ['-Inf, first sample', wav([-Infinity, 0.5]), 0],
    ['NaN, WAVE_FORMAT_EXTENSIBLE', wav([0.25, NaN], { extensible: true }), 1],
    ['NaN at 44.1 kHz', wav([0.25, 0.5, NaN], { rate: 44100 }), 2],
  ];
  for (const [what, bytes, frame] of cases) {
    assert.throws(() => parseWav(bytes, 'speech.wav'), {
      message: `speech.wav: sample ${frame} is not finite`,
    }, what);
  }
});

test('decodeTo16k refuses it with the same line', async () => {
  await assert.rejects(decodeTo16k(wav([0.5, NaN, 0.5]), 'voice.wav'), {
    message: 'voice.wav: sample 1 is not finite',
  });
});

test('finite float and PCM WAVs read as nldf reads them', () => {
  const float = parseWav(wav([0.5, -0.25, 1e-3, 3e-3], { channels: 2 }), 'a.wav');
  assert.equal(float.rate, 16000);
  const f = Math.fround;
  assert.deepEqual([...float.samples], [0.125, f(f(f(1e-3) + f(3e-3)) / 2)]);
  const pcm = parseWav(wav([16384, -32768, 1], { float: false }), 'b.wav');
  assert.deepEqual([...pcm.samples], [0.5, -1, 1 / 32768]);
  const huge = parseWav(wav([3.4e38, -3.4e38]), 'c.wav');
  assert.deepEqual([...huge.samples], [Math.fround(3.4e38), Math.fround(-3.4e38)]);
});
