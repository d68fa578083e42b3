// Audio for the page: WAV files to 16 kHz mono samples, and the microphone's newest samples.

export const RATE = 16000;

// PCM or float WAV bytes to { rate, samples } (mono: the channels' mean, as nldf reads
// them), or null when the file is a WAV the parser does not handle (then Web Audio decodes).
// A NaN or infinite sample throws, naming `name` and the sample's frame, as nldf refuses it.
export function parseWav(bytes, name = 'the WAV file') {
  const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  const tag = (at) => String.fromCharCode(...bytes.subarray(at, at + 4));
  if (bytes.length < 12 || tag(0) !== 'RIFF' || tag(8) !== 'WAVE') return null;
  let fmt = null;
  let data = null;
  for (let pos = 12; pos + 8 <= bytes.length; ) {
    const id = tag(pos);
    const size = view.getUint32(pos + 4, true);
    const body = pos + 8;
    if (id === 'fmt ' && size >= 16) {
      let format = view.getUint16(body, true);
      if (format === 0xfffe && size >= 26) format = view.getUint16(body + 24, true);
      fmt = {
        format,
        channels: view.getUint16(body + 2, true),
        rate: view.getUint32(body + 4, true),
        bits: view.getUint16(body + 14, true),
      };
    } else if (id === 'data') {
      data = { start: body, end: Math.min(bytes.length, body + size) };
      break;
    }
    pos = body + size + (size & 1);
  }
  if (!fmt || !data || fmt.channels === 0) return null;
  const { format, channels, bits } = fmt;
  const width = bits / 8;
  let read;
  if (format === 1 && [8, 16, 24, 32].includes(bits)) {
    const scale = 1 / 2 ** (bits - 1);
    read = (at) => {
      let v;
      if (bits === 8) v = view.getUint8(at) - 128;
      else if (bits === 16) v = view.getInt16(at, true);
      else if (bits === 24) v = (view.getUint8(at) | (view.getUint8(at + 1) << 8) | (view.getInt8(at + 2) << 16));
      else v = view.getInt32(at, true);
      return v * scale;
    };
  } else if (format === 3 && bits === 32) {
    read = (at) => view.getFloat32(at, true);
  } else {
    return null;
  }
  const frames = Math.floor((data.end - data.start) / (width * channels));
  const samples = new Float32Array(frames);
  for (let i = 0; i < frames; i++) {
    let sum = 0;
    for (let c = 0; c < channels; c++) {
      const v = read(data.start + (i * channels + c) * width);
      if (!Number.isFinite(v)) throw notFinite(name, i);
      sum = Math.fround(sum + Math.fround(v));
    }
    samples[i] = sum / channels;
  }
  return { rate: fmt.rate, samples };
}

// nldf's words for a sample that is NaN or infinite (`decode_wav`, core/src/audio.rs).
function notFinite(name, frame) {
  return new Error(`${name}: sample ${frame} is not finite`);
}

// Mono samples at `rate` resampled to 16 kHz by the browser (OfflineAudioContext).
async function resample(samples, rate) {
  const length = Math.max(1, Math.round((samples.length * RATE) / rate));
  const ctx = new OfflineAudioContext(1, length, RATE);
  const buffer = ctx.createBuffer(1, samples.length, rate);
  buffer.copyToChannel(samples, 0);
  const source = ctx.createBufferSource();
  source.buffer = buffer;
  source.connect(ctx.destination);
  source.start();
  return (await ctx.startRendering()).getChannelData(0).slice();
}

// Any audio file the browser decodes, as 16 kHz mono samples: a 16 kHz WAV bit for bit as
// nldf reads it, other rates and formats through Web Audio.
export async function decodeTo16k(bytes, name = 'the audio file') {
  const wav = parseWav(bytes, name);
  if (wav) {
    if (wav.samples.length === 0) throw new Error(`${name} holds no samples`);
    return { samples: wav.rate === RATE ? wav.samples : await resample(wav.samples, wav.rate), sourceRate: wav.rate };
  }
  let buffer;
  try {
    const ctx = new OfflineAudioContext(1, 1, RATE);
    buffer = await ctx.decodeAudioData(bytes.slice().buffer);
  } catch (e) {
    throw new Error(`${name} is not audio the browser can decode (${e.message || e})`);
  }
  const mono = new Float32Array(buffer.length);
  for (let c = 0; c < buffer.numberOfChannels; c++) {
    const ch = buffer.getChannelData(c);
    for (let i = 0; i < mono.length; i++) mono[i] += ch[i] / buffer.numberOfChannels;
  }
  if (mono.length === 0) throw new Error(`${name} holds no samples`);
  const bad = mono.findIndex((v) => !Number.isFinite(v));
  if (bad >= 0) throw notFinite(name, bad);
  return { samples: buffer.sampleRate === RATE ? mono : await resample(mono, buffer.sampleRate), sourceRate: buffer.sampleRate };
}

// The last `capacity` samples of a live signal; `count` counts every sample pushed.
export class Ring {
  constructor(capacity) {
    this.data = new Float32Array(capacity);
    this.count = 0;
  }
  push(block) {
    const n = this.data.length;
    for (let i = 0; i < block.length; i++) this.data[(this.count + i) % n] = block[i];
    this.count += block.length;
  }
  // Sample number `i` of the signal (one of the last `capacity`).
  at(i) {
    return this.data[i % this.data.length];
  }
}

// Linear-interpolating resampler for a stream, for a context that cannot run at 16 kHz.
class StreamResampler {
  constructor(from) {
    this.step = from / RATE;
    this.pos = 0;
    this.prev = 0;
  }
  process(block) {
    const out = [];
    while (this.pos < block.length) {
      const i = Math.floor(this.pos);
      const frac = this.pos - i;
      const a = i === 0 ? this.prev : block[i - 1];
      const b = block[i];
      out.push(a + (b - a) * frac);
      this.pos += this.step;
    }
    this.pos -= block.length;
    this.prev = block[block.length - 1];
    return Float32Array.from(out);
  }
}

// The microphone, captured by an AudioWorklet into `ring` at 16 kHz. Returns stop().
export async function startMicrophone(ring, workletUrl) {
  if (!navigator.mediaDevices?.getUserMedia) throw new Error('this browser gives no microphone access');
  const stream = await navigator.mediaDevices.getUserMedia({
    audio: { channelCount: 1, echoCancellation: false, noiseSuppression: false, autoGainControl: false },
  });
  let ctx;
  let source;
  try {
    ctx = new AudioContext({ sampleRate: RATE });
    source = ctx.createMediaStreamSource(stream);
  } catch {
    // Some browsers refuse a microphone in a context at another rate than the device's.
    await ctx?.close();
    ctx = new AudioContext();
    source = ctx.createMediaStreamSource(stream);
  }
  const resampler = ctx.sampleRate === RATE ? null : new StreamResampler(ctx.sampleRate);
  await ctx.audioWorklet.addModule(workletUrl);
  const node = new AudioWorkletNode(ctx, 'nldf-capture', { numberOfInputs: 1, numberOfOutputs: 0 });
  node.port.onmessage = (e) => ring.push(resampler ? resampler.process(e.data) : e.data);
  source.connect(node);
  await ctx.resume();
  return async () => {
    source.disconnect();
    node.port.onmessage = null;
    stream.getTracks().forEach((t) => t.stop());
    await ctx.close();
  };
}
