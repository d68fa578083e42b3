// An nldf frame graph's metadata, read from the ONNX bytes themselves (onnxruntime-web
// does not expose metadata_props): ModelProto field 14, repeated StringStringEntryProto
// {key = 1, value = 2}.

// Length-delimited and varint fields of one protobuf message, in order.
function* fields(bytes, start = 0, end = bytes.length) {
  let pos = start;
  const varint = () => {
    let value = 0;
    let scale = 1;
    for (let i = 0; i < 10; i++) {
      if (pos >= end) throw new Error('truncated varint');
      const b = bytes[pos++];
      value += (b & 0x7f) * scale;
      if (b < 0x80) return value;
      scale *= 128;
    }
    throw new Error('varint longer than 10 bytes');
  };
  while (pos < end) {
    const tag = varint();
    const field = Math.floor(tag / 8);
    const wire = tag & 7;
    if (field === 0) throw new Error('field number 0');
    if (wire === 0) {
      yield { field, wire, value: varint() };
    } else if (wire === 1 || wire === 5) {
      const n = wire === 1 ? 8 : 4;
      if (pos + n > end) throw new Error('truncated fixed-width field');
      yield { field, wire, start: pos, end: pos + n };
      pos += n;
    } else if (wire === 2) {
      const n = varint();
      if (pos + n > end) throw new Error(`field ${field} runs past the end of the file`);
      yield { field, wire, start: pos, end: pos + n };
      pos += n;
    } else {
      throw new Error(`unsupported wire type ${wire}`);
    }
  }
}

const utf8 = new TextDecoder('utf-8', { fatal: true });

// The ModelProto's metadata_props as a Map, and whether it had a graph (field 7).
export function readMetadata(bytes) {
  const props = new Map();
  let graph = false;
  for (const f of fields(bytes)) {
    if (f.field === 7 && f.wire === 2) graph = true;
    if (f.field !== 14 || f.wire !== 2) continue;
    let key = '';
    let value = '';
    for (const g of fields(bytes, f.start, f.end)) {
      if (g.wire !== 2) continue;
      if (g.field === 1) key = utf8.decode(bytes.subarray(g.start, g.end));
      if (g.field === 2) value = utf8.decode(bytes.subarray(g.start, g.end));
    }
    props.set(key, value);
  }
  return { props, graph };
}

// What the page needs from a frame graph's metadata; throws a one-line error naming what is
// wrong for a ray graph, a foreign model or a file that is not ONNX at all.
export function frameModelInfo(bytes, name = 'the model') {
  if (!(bytes instanceof Uint8Array) || bytes.length === 0) {
    throw new Error(`${name} is empty, not an ONNX model`);
  }
  let meta;
  try {
    meta = readMetadata(bytes);
  } catch (e) {
    throw new Error(`${name} is not an ONNX model (${e.message})`);
  }
  if (!meta.graph) throw new Error(`${name} is not an ONNX model (it holds no graph)`);
  const p = meta.props;
  const format = p.get('nldf.format');
  if (format === 'nldf-student') {
    throw new Error(
      `${name} is an nldf ray graph, not a frame graph: export it with \`nldf export --frame\``,
    );
  }
  if (format !== 'nldf-frame') {
    throw new Error(
      format === undefined
        ? `${name} is not an nldf model (no nldf.format metadata)`
        : `${name} is not an nldf frame graph (nldf.format is "${format}")`,
    );
  }
  const json = (key) => {
    const text = p.get(key);
    if (text === undefined) throw new Error(`${name}: metadata ${key} is missing`);
    try {
      return JSON.parse(text);
    } catch {
      throw new Error(`${name}: metadata ${key} is not JSON`);
    }
  };
  const audio = json('nldf.frame_audio');
  for (const k of ['sample_rate', 'samples', 'offset', 'samples_per_frame', 'hop', 'win', 'window']) {
    if (!Number.isInteger(audio[k])) throw new Error(`${name}: nldf.frame_audio.${k} is not an integer`);
  }
  const ahead = p.has('nldf.audio_ahead') ? json('nldf.audio_ahead') : null;
  if (ahead !== null && !(Number.isInteger(ahead) && ahead > 0 && ahead <= audio.window / 2)) {
    throw new Error(`${name}: nldf.audio_ahead is "${p.get('nldf.audio_ahead')}", not 1 to ${audio.window / 2}`);
  }
  audio.readEnd = readEnd(audio, json('nldf.audio_attention') === true, ahead);
  if (audio.sample_rate !== 16000) {
    throw new Error(`${name}: audio at ${audio.sample_rate} Hz, the page handles 16000 Hz`);
  }
  const width = json('nldf.image_width');
  const height = json('nldf.image_height');
  if (!(Number.isInteger(width) && Number.isInteger(height) && width > 0 && height > 0)) {
    throw new Error(`${name}: image size ${width} x ${height} is not valid`);
  }
  // A learned upsampler: the student runs on a grid `upsample` times coarser, and `keep` is
  // that grid's.
  const upsample = p.has('nldf.frame_upsample') ? Number(p.get('nldf.frame_upsample')) : 1;
  if (![1, 2, 4, 8].includes(upsample) || width % upsample || height % upsample) {
    throw new Error(`${name}: nldf.frame_upsample is "${p.get('nldf.frame_upsample')}", not 1, 2, 4 or 8 dividing ${width} x ${height}`);
  }
  const pose = json('nldf.default_pose');
  if (!(Array.isArray(pose) && pose.length === 4 && pose.every((r) => Array.isArray(r) && r.length === 4))) {
    throw new Error(`${name}: nldf.default_pose is not 4 rows of 4`);
  }
  const lo = json('nldf.bounds_lo');
  const hi = json('nldf.bounds_hi');
  return {
    audio,
    fps: json('nldf.fps'),
    width,
    height,
    upsample,
    keepWidth: width / upsample,
    keepHeight: height / upsample,
    defaultPose: pose.flat().map(Number),
    centre: [0, 1, 2].map((i) => Math.fround(Math.fround(lo[i] + hi[i]) * 0.5)),
    props: p,
  };
}

// Row-major 4 x 4 product a * b.
export function matmul(a, b) {
  const out = new Array(16).fill(0);
  for (let i = 0; i < 4; i++) {
    for (let j = 0; j < 4; j++) {
      let s = 0;
      for (let k = 0; k < 4; k++) s += a[4 * i + k] * b[4 * k + j];
      out[4 * i + j] = s;
    }
  }
  return out;
}

// nldf's turn_about(centre, yaw, pitch) * c2w, row-major: the camera turned about the head
// box's centre, yaw about y after pitch about x (radians).
export function turnedPose(c2w, centre, yaw, pitch) {
  const [cx, cy, cz] = centre;
  const t = (x, y, z) => [1, 0, 0, x, 0, 1, 0, y, 0, 0, 1, z, 0, 0, 0, 1];
  const cyw = Math.cos(yaw), syw = Math.sin(yaw);
  const cp = Math.cos(pitch), sp = Math.sin(pitch);
  const ry = [cyw, 0, syw, 0, 0, 1, 0, 0, -syw, 0, cyw, 0, 0, 0, 0, 1];
  const rx = [1, 0, 0, 0, 0, cp, -sp, 0, 0, sp, cp, 0, 0, 0, 0, 1];
  const turn = matmul(matmul(matmul(t(cx, cy, cz), ry), rx), t(-cx, -cy, -cz));
  return matmul(turn, c2w);
}

// Frame `frame`'s chunk of the 16 kHz track `samples`: `layout.samples` samples from
// `frame * samples_per_frame + offset`, NaN where that lies outside the track.
export function chunkFor(layout, samples, frame) {
  const out = new Float32Array(layout.samples);
  const start = frame * layout.samples_per_frame + layout.offset;
  for (let i = 0; i < out.length; i++) {
    const t = start + i;
    out[i] = t >= 0 && t < samples.length ? samples[t] : NaN;
  }
  return out;
}

// One past the last sample of a chunk that the graph reads. With attention, every sample:
// the neighbours' windows reach the chunk's end. Without, the frame's own window alone, whose
// rows end `ahead` feature frames past its centre (all `window / 2` unless nldf.audio_ahead
// says fewer, a short-lookahead student's): the frame's instant lies at `-offset`, and the
// last row read ends half a Hann window after its centre, `ahead - 1` hops past the instant.
export function readEnd(layout, attention, ahead) {
  if (attention) return layout.samples;
  const rows = ahead ?? layout.window / 2;
  const lookahead = (rows - 1) * layout.hop + layout.win - Math.floor(layout.win / 2);
  return Math.min(layout.samples, -layout.offset + lookahead);
}

// The newest samples of a live signal, as the chunk of the frame whose read audio ends now:
// they end at `layout.readEnd` (the chunk's end without it), NaN in front while fewer have
// arrived and NaN after it, where the graph reads nothing it uses.
export function liveChunk(layout, ring) {
  const out = new Float32Array(layout.samples).fill(NaN);
  const end = layout.readEnd ?? out.length;
  const have = Math.min(ring.count, end);
  for (let i = 0; i < have; i++) {
    out[end - have + i] = ring.at(ring.count - have + i);
  }
  return out;
}
