// The page: an nldf frame graph in onnxruntime-web (WASM, SIMD, threads), driven by a WAV
// file or the microphone, the head turned by dragging or by the sliders. A WAV's frames skip
// still pixels (./still.js) unless the box is unticked; the microphone's are always full.
// window.nldf is the hook the tests and the benchmark drive it through.
import * as ort from '../ort/ort.wasm.min.mjs';
import { frameModelInfo, turnedPose, chunkFor, liveChunk } from './model.js';
import { RATE, decodeTo16k, Ring, startMicrophone } from './audio.js';
import { SKIP_CONFIG, StillSkipper, probeFrames } from './still.js';
import { wasmSimd } from './wasm.js';

const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(location.search);
const DEG = Math.PI / 180;

const errors = [];
function showError(message) {
  errors.push(message);
  const box = $('error');
  box.textContent = message;
  box.hidden = false;
}
function clearError() {
  $('error').hidden = true;
  $('error').textContent = '';
}
window.addEventListener('error', (e) => showError(`page error: ${e.message}`));
window.addEventListener('unhandledrejection', (e) => showError(`page error: ${e.reason?.message ?? e.reason}`));

// The runtime: WASM with SIMD and 2-4 threads where the page is cross-origin isolated.
const simd = wasmSimd();
const cores = navigator.hardwareConcurrency || 2;
const threads = Number(params.get('threads')) || (crossOriginIsolated ? Math.min(4, Math.max(2, cores)) : 1);
ort.env.wasm.wasmPaths = new URL('../ort/', import.meta.url).href;
ort.env.wasm.numThreads = threads;
ort.env.wasm.proxy = false;
ort.env.logLevel = 'error';
$('runtime').textContent =
  `onnxruntime-web ${ort.env.versions?.web ?? ''}, WASM${simd ? ' SIMD' : ' without SIMD'}, ${threads} thread${threads > 1 ? 's' : ''}` +
  (crossOriginIsolated ? '' : ' (page not cross-origin isolated: one thread)');

const state = {
  model: null, // { session, info, name, all (every pixel kept), skipper }
  track: null, // { samples, name, frames }
  frame: 0, // the track's frame shown when not playing
  yaw: 0,
  pitch: 0,
  dirty: true,
  playback: null, // { ctx, source, start }
  mic: null, // { ring, stop }
  lastMicChunk: null,
  rendering: false,
  choosing: false, // the live loop waits while the page times frame graphs
  times: [], // { at, nRays, headRays } of the frames drawn in the last 2 s
  last: null, // the last frame: { kind, nRays, headRays, keep }
};

// Session runs one at a time: the live loop and the hook share this queue.
let queue = Promise.resolve();
function exclusive(fn) {
  const p = queue.then(fn);
  queue = p.catch(() => {});
  return p;
}

const canvas = $('canvas');
const ctx2d = canvas.getContext('2d', { willReadFrequently: true });

function pose() {
  const info = state.model.info;
  return turnedPose(info.defaultPose, info.centre, state.yaw, state.pitch);
}

// The graph's frame for `chunk` from camera-to-world `c2w` (row-major), only the pixels
// `keep` marks (a 0/1 mask, row-major; null: every pixel) rendered: { image, nRays }.
async function runGraph(chunk, c2w, keep, model = state.model) {
  const { session, info, all } = model;
  const { width, height, keepWidth, keepHeight } = info;
  const out = await session.run({
    audio: new ort.Tensor('float32', chunk, [chunk.length]),
    pose: new ort.Tensor('float32', Float32Array.from(c2w), [4, 4]),
    keep: new ort.Tensor('bool', keep ?? all, [keepHeight, keepWidth]),
  }, ['image', 'n_rays']);
  const image = out.image.data;
  const nRays = Number(out.n_rays.data[0]);
  for (const t of Object.values(out)) t.dispose?.();
  if (image.length !== width * height * 3) {
    throw new Error(`the graph gave ${image.length} values, expected ${width} x ${height} x 3`);
  }
  return { image, nRays };
}

// Still pixels are skipped while the box is ticked (with a learned upsampler, through the
// coarse cells they read: ./still.js).
const skipping = () => $('skip').checked && !!state.model;
const probeChunks = () => probeFrames(state.track.frames, SKIP_CONFIG.probes).map((f) => trackChunk(f));

// One frame: the graph's frame for `chunk` from the camera turned by yaw/pitch (with `skip`,
// the track's frame through the still-pixel skipper), drawn on the canvas; returns the
// canvas's pixels as RGB.
async function render(chunk, yaw, pitch, skip = false) {
  const info = state.model.info;
  const c2w = turnedPose(info.defaultPose, info.centre, yaw, pitch);
  let frame;
  if (skip && state.track) {
    frame = await state.model.skipper.render(runGraph, c2w, chunk, probeChunks);
  } else {
    const out = await runGraph(chunk, c2w, null);
    frame = { image: out.image, kind: 'full', nRays: out.nRays, headRays: out.nRays, keep: null };
  }
  state.last = frame;
  return draw(frame.image);
}

// Draws a frame on the canvas (8 bits, nldf's rounding); returns the canvas's pixels as RGB.
function draw(image) {
  const { width, height } = state.model.info;
  const rgba = new ImageData(width, height);
  for (let i = 0, n = width * height; i < n; i++) {
    for (let c = 0; c < 3; c++) {
      const v = image[3 * i + c];
      rgba.data[4 * i + c] = Math.round(Math.min(1, Math.max(0, v)) * 255);
    }
    rgba.data[4 * i + 3] = 255;
  }
  ctx2d.putImageData(rgba, 0, 0);
  const back = ctx2d.getImageData(0, 0, width, height).data;
  const rgb = new Uint8ClampedArray(width * height * 3);
  for (let i = 0, n = width * height; i < n; i++) {
    rgb[3 * i] = back[4 * i];
    rgb[3 * i + 1] = back[4 * i + 1];
    rgb[3 * i + 2] = back[4 * i + 2];
  }
  return rgb;
}

// Reads and checks a frame graph and opens its session: { session, info, name, all, skipper }.
async function openModel(source, name) {
  let bytes = source;
  if (typeof source === 'string') {
    name ??= source;
    const res = await fetch(source);
    if (!res.ok) throw new Error(`${name}: HTTP ${res.status}`);
    bytes = new Uint8Array(await res.arrayBuffer());
  } else if (source instanceof ArrayBuffer) {
    bytes = new Uint8Array(source);
  }
  name ??= 'the model';
  const info = frameModelInfo(bytes, name);
  let session;
  try {
    session = await ort.InferenceSession.create(bytes, {
      executionProviders: ['wasm'],
      graphOptimizationLevel: 'all',
    });
  } catch (e) {
    throw new Error(`${name}: onnxruntime-web cannot load it (${e.message ?? e})`);
  }
  const missing = ['audio', 'pose', 'keep'].filter((i) => !session.inputNames.includes(i))
    .map((i) => `"${i}" input`)
    .concat(['image', 'n_rays'].filter((o) => !session.outputNames.includes(o)).map((o) => `"${o}" output`));
  if (missing.length) {
    await session.release();
    throw new Error(`${name}: the graph has no ${missing.join(' or ')} (an older export? run nldf export --frame again)`);
  }
  const all = new Uint8Array(info.keepWidth * info.keepHeight).fill(1);
  const skipper = new StillSkipper(info.width, info.height, SKIP_CONFIG, info.upsample);
  return { session, info, name, all, skipper };
}

const shortName = (name) => name.split('/').pop();

// Makes `model` the page's model (releasing the one before); `note` is said after its line.
async function install(model, note = '') {
  const { info, name } = model;
  await exclusive(async () => {
    if (state.model !== model) await state.model?.session.release();
    state.model = model;
  });
  canvas.width = info.width;
  canvas.height = info.height;
  $('drop').style.aspectRatio = `${info.width} / ${info.height}`;
  $('drop').style.height = 'auto';
  $('model-status').textContent =
    `${shortName(name)}: ${info.width} x ${info.height}, ${info.fps} fps, ` +
    `${info.audio.samples} samples (${(info.audio.samples / RATE).toFixed(2)} s) of audio a frame` +
    (info.upsample > 1
      ? `; learned upsampler x${info.upsample} (rays on ${info.keepWidth} x ${info.keepHeight})`
      : '');
  $('choice').textContent = note;
  $('choice').hidden = !note;
  clearError();
  state.dirty = true;
  if (state.track) setTrack(state.track.samples, state.track.name);
  return { width: info.width, height: info.height, upsample: info.upsample, fps: info.fps, audio: info.audio, threads };
}

async function loadModel(source, name) {
  return install(await openModel(source, name));
}

// The audio of frame `f` of the track, looped (silence without a track), for a graph of `info`.
const loopedChunk = (info, f) =>
  state.track ? chunkFor(info.audio, state.track.samples, f % state.track.frames) : new Float32Array(info.audio.samples);

// Frames per second of `model`'s runs here: `n` full frames after one untimed, the head
// turning a little as a moving head does (every ray cast: what skipping cannot save), with
// the track's audio (silence without one).
async function affordable(model, n) {
  const { info } = model;
  const once = (i) => runGraph(loopedChunk(info, i), turnedPose(info.defaultPose, info.centre, 0.2 * Math.sin(i / 7), 0), null, model);
  return exclusive(async () => {
    await once(0);
    const t0 = performance.now();
    for (let i = 1; i <= n; i++) await once(i);
    return (1000 * n) / (performance.now() - t0);
  });
}

// Picks what this browser can afford among frame graphs (URLs or bytes): each is timed on
// `n` frames of a moving head; ranked by the rays they cast (native rays first, then coarser
// grids), the first that reaches `target` frames/s (default: the graphs' own frame rate)
// is kept, else the fastest, and the page says which and why. Resolves to { picked, target,
// reached, measured: [{ name, fps, rays, upsample }] } in rank order.
async function choose(sources, target = null, n = 6) {
  if (!sources.length) throw new Error('no frame graph to choose from');
  const models = [];
  state.choosing = true;
  try {
    for (const s of sources) {
      const [source, name] = Array.isArray(s) ? s : [s, undefined];
      models.push(await openModel(source, name));
    }
    const rays = (m) => m.info.keepWidth * m.info.keepHeight;
    models.sort((a, b) => rays(b) - rays(a));
    target ??= Math.max(...models.map((m) => m.info.fps));
    const measured = [];
    for (const m of models) measured.push({ name: shortName(m.name), fps: await affordable(m, n), rays: rays(m), upsample: m.info.upsample });
    let at = measured.findIndex((m) => m.fps >= target);
    const reached = at >= 0;
    if (!reached) at = measured.reduce((best, m, i) => (m.fps > measured[best].fps ? i : best), 0);
    const others = measured.filter((_, i) => i !== at).map((m) => `${m.name} ${m.fps.toFixed(1)}`);
    const note =
      `picked ${measured[at].name}: ${measured[at].fps.toFixed(1)} frames/s measured here for a moving head, ` +
      (reached ? `reaching ${target} frames/s` : `under ${target} frames/s: frames will be dropped`) +
      (others.length ? ` (also timed: ${others.join(', ')})` : '') + '.';
    for (const [i, m] of models.entries()) if (i !== at) await m.session.release();
    await install(models[at], note);
    return { picked: measured[at].name, target, reached, measured };
  } catch (e) {
    for (const m of models) if (m !== state.model) await m.session.release().catch(() => {});
    throw e;
  } finally {
    state.choosing = false;
  }
}

function setTrack(samples, name) {
  const spf = state.model?.info.audio.samples_per_frame ?? 640;
  state.track = { samples, name, frames: Math.floor(samples.length / spf) };
  state.model?.skipper.reset();
  state.frame = 0;
  state.dirty = true;
  $('play').disabled = false;
  $('audio-status').textContent =
    `${name}: ${(samples.length / RATE).toFixed(2)} s, ${state.track.frames} frames`;
}

async function setWav(bytes, name = 'the WAV file') {
  stopPlayback();
  const { samples, sourceRate } = await decodeTo16k(bytes instanceof Uint8Array ? bytes : new Uint8Array(bytes), name);
  setTrack(samples, name);
  return { samples: samples.length, frames: state.track.frames, sourceRate };
}

function trackChunk(f) {
  if (!state.model) throw new Error('no model loaded');
  if (!state.track) throw new Error('no audio loaded');
  return chunkFor(state.model.info.audio, state.track.samples, f);
}

// Playback of the track; the live loop renders the frame at the playing position.
let audioCtx = null;
async function play() {
  if (!state.track) return;
  stopPlayback();
  await stopMic();
  audioCtx ??= new AudioContext();
  await audioCtx.resume();
  const { samples } = state.track;
  const buffer = audioCtx.createBuffer(1, samples.length, RATE);
  buffer.copyToChannel(samples, 0);
  const source = audioCtx.createBufferSource();
  source.buffer = buffer;
  source.connect(audioCtx.destination);
  const start = audioCtx.currentTime + 0.05;
  source.start(start);
  source.onended = () => {
    if (state.playback?.source === source) stopPlayback();
  };
  state.playback = { source, start };
  $('play').textContent = 'Stop';
  $('play').classList.add('on');
}

function stopPlayback() {
  const p = state.playback;
  if (!p) return;
  state.playback = null;
  try {
    p.source.stop();
  } catch {}
  $('play').textContent = 'Play';
  $('play').classList.remove('on');
  state.dirty = true;
}

async function startMic() {
  if (state.mic) return;
  stopPlayback();
  const ring = new Ring(RATE * 10);
  const stop = await startMicrophone(ring, new URL('./capture-worklet.js', import.meta.url).href);
  state.mic = { ring, stop };
  $('mic').classList.add('on');
  $('audio-status').textContent = 'microphone: the head follows the newest samples';
}

async function stopMic() {
  const mic = state.mic;
  if (!mic) return;
  state.mic = null;
  $('mic').classList.remove('on');
  await mic.stop();
  state.dirty = true;
  $('audio-status').textContent = state.track ? `${state.track.name}` : 'no audio: the head is silent';
}

function micChunk() {
  if (!state.mic) throw new Error('the microphone is off');
  return liveChunk(state.model.info.audio, state.mic.ring);
}

// The live loop: the frame the audio is at, whenever the previous one is done.
function tick() {
  requestAnimationFrame(tick);
  if (!state.model || state.rendering || state.choosing) return;
  let chunk;
  let skip = false;
  const info = state.model.info;
  if (state.playback) {
    const elapsed = audioCtx.currentTime - state.playback.start - (audioCtx.outputLatency || 0);
    state.frame = Math.max(0, Math.min(state.track.frames - 1, Math.floor(elapsed * info.fps)));
    chunk = trackChunk(state.frame);
    skip = skipping();
  } else if (state.mic) {
    chunk = micChunk();
    state.lastMicChunk = chunk;
  } else if (state.dirty) {
    chunk = state.track ? trackChunk(state.frame) : new Float32Array(info.audio.samples);
    skip = skipping();
  } else {
    return;
  }
  state.dirty = false;
  state.rendering = true;
  const { yaw, pitch } = state;
  exclusive(() => render(chunk, yaw, pitch, skip))
    .then(() => countFrame())
    .catch((e) => {
      showError(`rendering failed: ${e.message ?? e}`);
      stopPlayback();
    })
    .finally(() => {
      state.rendering = false;
    });
}

// Frames per second and the share of the head's rays re-rendered, over the last 2 s.
function countFrame() {
  const now = performance.now();
  const { nRays, headRays } = state.last;
  state.times.push({ at: now, nRays, headRays });
  while (state.times.length > 1 && now - state.times[0].at > 2000) state.times.shift();
  const n = state.times.length - 1;
  const fps = n > 0 ? (1000 * n) / (now - state.times[0].at) : 0;
  const rays = state.times.reduce((s, t) => s + t.nRays, 0);
  const head = state.times.reduce((s, t) => s + t.headRays, 0);
  $('fps').textContent = `${fps.toFixed(1)} fps`;
  $('rays').textContent = head > 0 ? `${Math.round((100 * rays) / head)} % of rays` : 'no head rays';
}

// The head's pose from the sliders and from dragging on the view.
function setPose(yawDeg, pitchDeg) {
  const clamp = (v, el) => Math.min(Number(el.max), Math.max(Number(el.min), v));
  yawDeg = clamp(yawDeg, $('yaw'));
  pitchDeg = clamp(pitchDeg, $('pitch'));
  $('yaw').value = yawDeg;
  $('pitch').value = pitchDeg;
  $('yaw-out').textContent = `${Number(yawDeg).toFixed(1)}°`;
  $('pitch-out').textContent = `${Number(pitchDeg).toFixed(1)}°`;
  state.yaw = yawDeg * DEG;
  state.pitch = pitchDeg * DEG;
  state.dirty = true;
}
$('yaw').addEventListener('input', () => setPose(Number($('yaw').value), Number($('pitch').value)));
$('pitch').addEventListener('input', () => setPose(Number($('yaw').value), Number($('pitch').value)));
$('reset').addEventListener('click', () => setPose(0, 0));

const view = $('drop');
let drag = null;
view.addEventListener('pointerdown', (e) => {
  drag = { x: e.clientX, y: e.clientY, yaw: Number($('yaw').value), pitch: Number($('pitch').value) };
  view.setPointerCapture(e.pointerId);
});
view.addEventListener('pointermove', (e) => {
  if (!drag) return;
  const perPixel = 90 / view.clientWidth;
  setPose(drag.yaw - (e.clientX - drag.x) * perPixel, drag.pitch - (e.clientY - drag.y) * perPixel);
});
const endDrag = () => {
  drag = null;
};
view.addEventListener('pointerup', endDrag);
view.addEventListener('pointercancel', endDrag);

// Files: picked, or dropped anywhere on the page (.onnx: a model, several: the page picks
// among them; anything else: audio).
async function openFiles(files) {
  const graphs = [...files].filter((f) => f.name.toLowerCase().endsWith('.onnx'));
  if (graphs.length > 1) {
    const sources = await Promise.all(graphs.map(async (f) => [new Uint8Array(await f.arrayBuffer()), f.name]));
    await choose(sources);
    return;
  }
  if (files[0]) await openFile(files[0]);
}
async function openFile(file) {
  const bytes = new Uint8Array(await file.arrayBuffer());
  if (file.name.toLowerCase().endsWith('.onnx')) {
    await loadModel(bytes, file.name);
  } else {
    await setWav(bytes, file.name);
    if (params.get('autoplay') !== '0') await play();
  }
}
const guarded = (fn) => (...args) => Promise.resolve().then(() => fn(...args)).catch((e) => showError(e.message ?? String(e)));
$('model-input').addEventListener('change', guarded(async (e) => openFiles(e.target.files)));
$('wav-input').addEventListener('change', guarded(async (e) => e.target.files[0] && openFile(e.target.files[0])));
document.addEventListener('dragover', (e) => {
  e.preventDefault();
  view.classList.add('dragover');
});
document.addEventListener('dragleave', () => view.classList.remove('dragover'));
document.addEventListener('drop', guarded(async (e) => {
  e.preventDefault();
  view.classList.remove('dragover');
  const files = e.dataTransfer?.files;
  if (files?.length) await openFiles(files);
}));
$('play').addEventListener('click', guarded(() => (state.playback ? stopPlayback() : play())));
$('skip').addEventListener('change', () => {
  state.model?.skipper.reset();
  state.dirty = true;
});
$('mic').addEventListener('click', guarded(() => (state.mic ? stopMic() : startMic())));

// `fn`, its error also shown on the page.
const shown = (fn) => (...args) => fn(...args).catch((e) => {
  showError(e.message);
  throw e;
});

// The hook: deterministic frames for the tests and the benchmark (yaw and pitch in radians).
const hook = {
  errors,
  threads,
  ortVersion: ort.env.versions?.web,
  loadModel: shown(loadModel),
  // Picks among frame graphs what this browser can afford (see choose above).
  choose: shown(choose),
  setWav,
  chunkFor: (f) => trackChunk(f),
  // The track's frame f, through the still-pixel skipper while its box is ticked.
  renderFrame: (f, yaw = 0, pitch = 0) => exclusive(() => render(trackChunk(f), yaw, pitch, skipping())),
  // How the last frame was made: { kind ('full', 'probed', 'partial'), nRays, headRays,
  // keep (the mask of a skipped frame, else null) }.
  lastFrame: () => {
    const { kind, nRays, headRays, keep } = state.last ?? {};
    return { kind, nRays, headRays, keep: keep ? Uint8Array.from(keep) : null };
  },
  renderChunk: (chunk, yaw = 0, pitch = 0) => exclusive(() => render(Float32Array.from(chunk), yaw, pitch)),
  // The microphone's newest chunk rendered: { chunk, rgb }.
  micFrame: (yaw = 0, pitch = 0) => exclusive(async () => {
    const chunk = micChunk();
    state.lastMicChunk = chunk;
    return { chunk, rgb: await render(chunk, yaw, pitch) };
  }),
  // A fresh skipper: the next skipped frame is a full one.
  resetSkipper: () => exclusive(() => state.model.skipper.reset()),
  lastMicChunk: () => state.lastMicChunk,
  micSamples: () => state.mic?.ring.count ?? 0,
  startMic,
  stopMic,
  play,
  stop: stopPlayback,
  state: () => ({
    model: state.model?.name ?? null,
    track: state.track ? { name: state.track.name, frames: state.track.frames } : null,
    frame: state.frame,
    playing: !!state.playback,
    mic: !!state.mic,
    crossOriginIsolated,
    threads,
    simd,
    // The live loop has nothing left to draw.
    idle: !state.dirty && !state.rendering,
  }),
  // Frames per second of `n` frames of the track (or of silence) after `warmup`: the whole
  // frame (graph, 8 bits, canvas), or the graph's run alone when `toCanvas` is false; full
  // frames with the head turning a little, or with `skip` the track's frames at the default
  // pose through a fresh still-pixel skipper (its full and probed frames included), with the
  // share of the head's rays re-rendered and, from an untimed pass after the timed one, the
  // skipped frames' error against full renders: PSNR over all frames, the worst frame's, and
  // the largest difference of any channel.
  bench: (n = 50, warmup = 5, toCanvas = true, skip = false) => exclusive(async () => {
    const info = state.model.info;
    if (skip && !state.track) throw new Error('skipping needs a track');
    const chunk = (f) => loopedChunk(info, f);
    const pose = (yaw) => turnedPose(info.defaultPose, info.centre, yaw, 0);
    const skipper = state.model.skipper;
    let rays = 0;
    let head = 0;
    const once = async (f, yaw) => {
      const frame = skip
        ? await skipper.render(runGraph, pose(0), chunk(f), probeChunks)
        : await runGraph(chunk(f), pose(yaw), null);
      rays += frame.nRays;
      head += frame.headRays ?? frame.nRays;
      if (toCanvas) draw(frame.image);
    };
    for (let i = 0; i < warmup; i++) await once(i, 0);
    skipper.reset();
    rays = 0;
    head = 0;
    const t0 = performance.now();
    for (let i = 0; i < n; i++) await once(i, skip ? 0 : 0.2 * Math.sin(i / 7));
    const ms = (performance.now() - t0) / n;
    skipper.reset();
    const error = skip ? await skipError(n, chunk, pose(0)) : {};
    return { frames: n, ms_per_frame: ms, fps: 1000 / ms, ray_share: head > 0 ? rays / head : null, ...error };
  }),
};
// The skipper's frames `0..n` (audio `chunk(f)`, pose `c2w`, from a fresh skipper) against
// full renders of the same frames: { psnr_vs_full, worst_frame_psnr, max_abs_error }, a PSNR
// null where the frames are identical.
async function skipError(n, chunk, c2w) {
  const skipper = state.model.skipper;
  const psnr = (mse) => (mse > 0 ? -10 * Math.log10(mse) : null);
  let total = 0;
  let count = 0;
  let worst = 0;
  let maxAbs = 0;
  for (let f = 0; f < n; f++) {
    const skipped = (await skipper.render(runGraph, c2w, chunk(f), probeChunks)).image;
    const full = (await runGraph(chunk(f), c2w, null)).image;
    let se = 0;
    for (let i = 0; i < full.length; i++) {
      const d = skipped[i] - full[i];
      se += d * d;
      maxAbs = Math.max(maxAbs, Math.abs(d));
    }
    total += se;
    count += full.length;
    worst = Math.max(worst, se / full.length);
  }
  skipper.reset();
  return { psnr_vs_full: psnr(total / count), worst_frame_psnr: psnr(worst), max_abs_error: maxAbs };
}

// `?model=URL` loads that graph; `?models=A,B,...` (default: the demo's frame graph in fp16,
// then with int8 products) picks what this browser can afford among them, at `?fps=`
// frames/s if given.
hook.ready = (async () => {
  const one = params.get('model');
  if (one === 'none') return;
  const url = (u) => [new URL(u, location.href).pathname, shortName(u)];
  try {
    if (one) {
      await hook.loadModel(...url(one));
    } else {
      const list = (params.get('models') ?? '../models/demo/frame.onnx,../models/demo/frame_int8.onnx').split(',').filter(Boolean);
      await hook.choose(list.map(url), Number(params.get('fps')) || null);
    }
  } catch (e) {
    $('model-status').textContent = 'no model';
  }
})();
window.nldf = hook;
setPose(0, 0);
requestAnimationFrame(tick);
