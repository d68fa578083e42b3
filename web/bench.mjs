// Frames per second of nldf frame graphs in headless Chromium (onnxruntime-web, WASM SIMD,
// threads), one JSON line per model: full frames with the head turning, and frames skipping
// still pixels at the default pose (skip_fps, and skip_ray_share: the share of the head's
// rays re-rendered). Each line records the machine, Chromium and whether its WebAssembly has
// SIMD (`simd`, the page's detection).
// node web/bench.mjs [--frames 50] [--warmup 5] [--threads 2] [--wav WAV] MODEL.onnx...
// (default model: models/demo/frame.onnx; default track: a 4 s voiced test signal).
// Needs scripts/web_env.sh.
import { chromium } from 'playwright-core';
import { execFileSync } from 'node:child_process';
import { existsSync, mkdtempSync, readFileSync, rmSync, statSync } from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { startServer } from './serve.mjs';

const here = path.dirname(fileURLToPath(import.meta.url));
const opts = { frames: 50, warmup: 5, threads: 2, chromium: '/usr/bin/chromium', models: [] };
const argv = process.argv.slice(2);
for (let i = 0; i < argv.length; i++) {
  const a = argv[i];
  if (['--frames', '--warmup', '--threads'].includes(a)) {
    const v = Number(argv[++i]);
    if (!Number.isInteger(v) || v < 0) throw new Error(`${a} needs a whole number`);
    opts[a.slice(2)] = v;
  } else if (a === '--chromium') opts.chromium = argv[++i];
  else if (a === '--wav') opts.wav = path.resolve(argv[++i]);
  else if (a.startsWith('--')) throw new Error(`unknown argument ${a}`);
  else opts.models.push(path.resolve(a));
}
if (opts.models.length === 0) opts.models.push(path.join(here, '..', 'models', 'demo', 'frame.onnx'));
for (const m of opts.wav ? [...opts.models, opts.wav] : opts.models) {
  if (!existsSync(m)) {
    console.error(`bench: ${m} is missing`);
    process.exit(2);
  }
}
if (!existsSync(opts.chromium)) {
  console.error(`bench: ${opts.chromium} is missing (run scripts/web_env.sh)`);
  process.exit(3);
}

// A voiced, wobbling test signal, 4 s at 16 kHz, as a 16-bit WAV.
function testWav(seconds = 4) {
  const n = 16000 * seconds;
  const buf = Buffer.alloc(44 + 2 * n);
  buf.write('RIFF', 0);
  buf.writeUInt32LE(36 + 2 * n, 4);
  buf.write('WAVEfmt ', 8);
  buf.writeUInt32LE(16, 16);
  buf.writeUInt16LE(1, 20);
  buf.writeUInt16LE(1, 22);
  buf.writeUInt32LE(16000, 24);
  buf.writeUInt32LE(32000, 28);
  buf.writeUInt16LE(2, 32);
  buf.writeUInt16LE(16, 34);
  buf.write('data', 36);
  buf.writeUInt32LE(2 * n, 40);
  for (let i = 0; i < n; i++) {
    const t = i / 16000;
    const v = 0.4 * Math.sin(2 * Math.PI * (150 + 60 * Math.sin(2.5 * t)) * t) * (0.55 + 0.45 * Math.sin(9 * t));
    buf.writeInt16LE(Math.round(v * 32767), 44 + 2 * i);
  }
  return buf;
}

const run = (cmd, args) => {
  try {
    return execFileSync(cmd, args, { encoding: 'utf8', stdio: ['ignore', 'pipe', 'ignore'] }).trim();
  } catch {
    return null;
  }
};
const common = {
  machine: os.cpus()[0]?.model ?? 'unknown',
  cores: os.cpus().length,
  os: `${os.type()} ${os.release()}`,
  commit: run('git', ['-C', here, 'rev-parse', '--short', 'HEAD']),
  chromium: run(opts.chromium, ['--version']),
  ort_web: JSON.parse(readFileSync(path.join(here, 'node_modules/onnxruntime-web/package.json'), 'utf8')).version,
};

const server = await startServer(0);
const base = `http://127.0.0.1:${server.address().port}`;
const profile = mkdtempSync(path.join(os.tmpdir(), 'nldf-bench-'));
let context;
let code = 0;
try {
  context = await chromium.launchPersistentContext(profile, {
    executablePath: opts.chromium,
    headless: true,
    args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
      '--disable-background-networking', '--disable-component-update', '--disable-sync'],
  });
  const page = context.pages()[0] ?? (await context.newPage());
  page.setDefaultTimeout(300_000);
  const errors = [];
  page.on('pageerror', (e) => errors.push(e.message));
  await page.route('**/bench/*', (route) => {
    const name = new URL(route.request().url()).pathname.split('/').pop();
    const track = () => (opts.wav ? readFileSync(opts.wav) : testWav());
    const body = name === 'track.wav' ? track() : readFileSync(opts.models[Number(name.split('.')[0])]);
    return route.fulfill({ status: 200, body, contentType: 'application/octet-stream' });
  });
  await page.goto(`${base}/?model=none&autoplay=0&threads=${opts.threads}`);
  await page.waitForFunction(() => window.nldf !== undefined);
  const state = await page.evaluate(() => window.nldf.state());
  if (!state.crossOriginIsolated) throw new Error('the page is not cross-origin isolated: no threads');
  if (typeof state.simd !== 'boolean') throw new Error('the page does not say whether WASM SIMD is there');
  await page.evaluate(async () => {
    const bytes = new Uint8Array(await (await fetch('/bench/track.wav')).arrayBuffer());
    await window.nldf.setWav(bytes, 'track.wav');
  });
  for (const [i, model] of opts.models.entries()) {
    const info = await page.evaluate((url) => window.nldf.loadModel(url, url), `/bench/${i}.onnx`);
    const frame = await page.evaluate(([n, w]) => window.nldf.bench(n, w, true), [opts.frames, opts.warmup]);
    const graph = await page.evaluate(([n, w]) => window.nldf.bench(n, w, false), [opts.frames, opts.warmup]);
    // The page skips still pixels of graphs without a learned upsampler only.
    const skip = info.upsample > 1
      ? null
      : await page.evaluate(([n, w]) => window.nldf.bench(n, w, true, true), [opts.frames, opts.warmup]);
    console.log(JSON.stringify({
      model: path.relative(process.cwd(), model),
      bytes: statSync(model).size,
      width: info.width,
      height: info.height,
      ...common,
      // The page's own detection (src/wasm.js), not an assumption.
      backend: `wasm (${state.simd ? 'SIMD' : 'no SIMD'}, ${state.threads} threads)`,
      simd: state.simd,
      threads: state.threads,
      frames: frame.frames,
      fps: Number(frame.fps.toFixed(2)),
      ms_per_frame: Number(frame.ms_per_frame.toFixed(2)),
      graph_fps: Number(graph.fps.toFixed(2)),
      track: opts.wav ? path.basename(opts.wav) : 'test signal, 4 s',
      upsample: info.upsample,
      skip_fps: skip ? Number(skip.fps.toFixed(2)) : null,
      skip_ray_share: skip ? Number(skip.ray_share.toFixed(4)) : null,
    }));
  }
  if (errors.length) throw new Error(`page errors: ${errors.join('; ')}`);
} catch (e) {
  console.error(`bench: ${String(e.message ?? e).split('\n')[0]}`);
  code = 1;
} finally {
  await context?.close().catch(() => {});
  server.close();
  rmSync(profile, { recursive: true, force: true });
}
process.exit(code);
