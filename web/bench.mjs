// Frames per second of nldf frame graphs in headless Chromium (onnxruntime-web, WASM SIMD,
// threads), one JSON line per model: full frames with the head turning, and frames skipping
// still pixels at the default pose (skip_fps, and skip_ray_share: the share of the head's
// rays re-rendered). Each line records the machine, Chromium and whether its WebAssembly has
// SIMD (`simd`, the page's detection).
// node web/bench.mjs --wav SPEECH.wav [--frames 50] [--warmup 5] [--threads 2] MODEL.onnx...
// (default model: models/demo/frame.onnx). The track is speech, never a tone: `nldf bench
// web` gives the synthetic scene's hidden voice.
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
if (!opts.wav) {
  console.error('bench: --wav SPEECH.wav is required (nldf bench web passes the synthetic scene\'s hidden voice)');
  process.exit(2);
}
for (const m of [...opts.models, opts.wav]) {
  if (!existsSync(m)) {
    console.error(`bench: ${m} is missing`);
    process.exit(2);
  }
}
if (!existsSync(opts.chromium)) {
  console.error(`bench: ${opts.chromium} is missing (run scripts/web_env.sh)`);
  process.exit(3);
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
    const body = readFileSync(name === 'track.wav' ? opts.wav : opts.models[Number(name.split('.')[0])]);
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
    // Still pixels skipped, as the page does (with a learned upsampler, through the coarse
    // cells they read).
    const skip = await page.evaluate(([n, w]) => window.nldf.bench(n, w, true, true), [opts.frames, opts.warmup]);
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
      track: path.basename(opts.wav),
      upsample: info.upsample,
      skip_fps: skip ? Number(skip.fps.toFixed(2)) : null,
      skip_ray_share: skip ? Number(skip.ray_share.toFixed(4)) : null,
      // The skipped frames against full renders of the same frames (untimed).
      skip_psnr: skip?.psnr_vs_full == null ? null : Number(skip.psnr_vs_full.toFixed(2)),
      skip_worst_psnr: skip?.worst_frame_psnr == null ? null : Number(skip.worst_frame_psnr.toFixed(2)),
      skip_max_abs: skip ? Number(skip.max_abs_error.toFixed(5)) : null,
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
