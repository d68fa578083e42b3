// Drives the page in Debian's headless Chromium (playwright-core, no downloaded browser):
// loads the frame graph, feeds a WAV through the file input and through the fake
// microphone, renders the requested frames at the requested poses with still-pixel skipping
// off, then the track's first frames at the default pose with it on, and writes what the
// canvas showed to an output folder for the Rust test to compare with nldf.
//
// node web/test/browser.mjs --wav WAV --out DIR [--frames 0,1,25] [--poses 0,0;0.3,-0.1]
//   [--skip-frames N] [--model URL] [--model-file PATH] [--mic] [--ray-graph PATH]
//   [--choose PATH,PATH] [--screenshot PNG] [--chromium PATH]
//
// DIR gets frame_<f>_<p>.rgb (raw RGB u8, pose number p), skip_<f>.rgb and, for a skipped
// frame, skip_<f>.keep (the page's mask, one byte a pixel), mic.f32 (the chunk the page
// used, raw little-endian f32) and mic.rgb, and result.json: sizes, files, how each skipping
// frame was made, what the page picked among the --choose graphs (at a target every graph
// reaches and at one none reaches) and on a fresh load with no model named, page and
// console errors.
import { chromium } from 'playwright-core';
import { execFileSync } from 'node:child_process';
import { mkdtempSync, mkdirSync, readFileSync, rmSync, writeFileSync, existsSync } from 'node:fs';
import { tmpdir } from 'node:os';
import path from 'node:path';
import { startServer } from '../serve.mjs';

function parseArgs(argv) {
  const args = { frames: [0], poses: [[0, 0]], skipFrames: 0, model: '/models/demo/frame.onnx', chromium: '/usr/bin/chromium', mic: false };
  for (let i = 0; i < argv.length; i++) {
    const key = argv[i];
    const value = () => {
      if (i + 1 >= argv.length) throw new Error(`${key} needs a value`);
      return argv[++i];
    };
    if (key === '--wav') args.wav = path.resolve(value());
    else if (key === '--out') args.out = path.resolve(value());
    else if (key === '--frames') args.frames = value().split(',').map(Number);
    else if (key === '--poses') args.poses = value().split(';').map((p) => p.split(',').map(Number));
    else if (key === '--skip-frames') args.skipFrames = Number(value());
    else if (key === '--model') args.model = value();
    else if (key === '--mic') args.mic = true;
    else if (key === '--ray-graph') args.rayGraph = path.resolve(value());
    else if (key === '--model-file') args.modelFile = path.resolve(value());
    else if (key === '--choose') args.choose = value().split(',').map((f) => path.resolve(f));
    else if (key === '--screenshot') args.screenshot = path.resolve(value());
    else if (key === '--chromium') args.chromium = value();
    else throw new Error(`unknown argument ${key}`);
  }
  if (!args.wav || !args.out) throw new Error('usage: browser.mjs --wav WAV --out DIR [options]');
  if (args.frames.some((f) => !Number.isInteger(f) || f < 0)) throw new Error('--frames: frame numbers are whole numbers');
  if (!Number.isInteger(args.skipFrames) || args.skipFrames < 0) throw new Error('--skip-frames: a whole number');
  if (args.poses.some((p) => p.length !== 2 || p.some((v) => !Number.isFinite(v)))) throw new Error('--poses: yaw,pitch in radians, separated by ;');
  return args;
}

const args = parseArgs(process.argv.slice(2));
// A hung browser must not hang the test that runs this.
const limit = setTimeout(() => {
  console.error('browser: gave up after 240 s');
  process.exit(4);
}, 240_000);
limit.unref();
if (!existsSync(args.chromium)) {
  console.error(`browser: ${args.chromium} is missing (run scripts/web_env.sh)`);
  process.exit(3);
}
if (!existsSync(args.wav)) {
  console.error(`browser: ${args.wav} is missing`);
  process.exit(2);
}
mkdirSync(args.out, { recursive: true });

const result = {
  chromium: execFileSync(args.chromium, ['--version'], { encoding: 'utf8' }).trim(),
  page_errors: [],
  console_errors: [],
  frames: [],
};
const server = await startServer(0);
const base = `http://127.0.0.1:${server.address().port}`;
const profile = mkdtempSync(path.join(tmpdir(), 'nldf-chromium-'));
let context;
let failed = null;
try {
  context = await chromium.launchPersistentContext(profile, {
    executablePath: args.chromium,
    headless: true,
    viewport: { width: 900, height: 640 },
    args: [
      '--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
      '--disable-background-networking', '--disable-component-update', '--disable-sync',
      '--autoplay-policy=no-user-gesture-required',
      '--use-fake-ui-for-media-stream', '--use-fake-device-for-media-stream',
      `--use-file-for-fake-audio-capture=${args.wav}`,
    ],
  });
  const page = context.pages()[0] ?? (await context.newPage());
  page.on('pageerror', (e) => result.page_errors.push(e.message));
  page.on('console', (m) => {
    if (m.type() === 'error') result.console_errors.push(m.text());
  });
  page.setDefaultTimeout(60_000);
  await page.goto(`${base}/?autoplay=0&model=${encodeURIComponent(args.model)}`);
  await page.waitForFunction(() => window.nldf !== undefined);
  await page.evaluate(() => window.nldf.ready);
  Object.assign(result, await page.evaluate(() => ({ ...window.nldf.state(), ort_version: window.nldf.ortVersion })));
  if (!result.model) throw new Error(`the page loaded no model: ${await page.evaluate(() => window.nldf.errors.join('; '))}`);

  // A ray graph picked by the user is refused with a line on the page, and the frame graph
  // is then picked back.
  if (args.rayGraph) {
    await page.setInputFiles('#model-input', args.rayGraph);
    await page.waitForFunction(() => window.nldf.errors.length > 0);
    result.ray_graph_error = await page.evaluate(() => window.nldf.errors.splice(0).join('; '));
    result.ray_graph_error_shown = await page.locator('#error').isVisible();
    await page.evaluate((url) => window.nldf.loadModel(url), args.model);
  }

  // A frame graph picked through the file input instead of the default one.
  if (args.modelFile) {
    const name = path.basename(args.modelFile);
    await page.setInputFiles('#model-input', args.modelFile);
    await page.waitForFunction((n) => window.nldf.state().model?.endsWith(n) || window.nldf.errors.length > 0, name);
    const errors = await page.evaluate(() => window.nldf.errors.join('; '));
    if (errors) throw new Error(`the page refused ${name}: ${errors}`);
    result.model = await page.evaluate(() => window.nldf.state().model);
    result.model_status = await page.locator('#model-status').textContent();
    result.skip_enabled = await page.isEnabled('#skip');
  }

  await page.setInputFiles('#wav-input', args.wav);
  await page.waitForFunction(() => window.nldf.state().track !== null || window.nldf.errors.length > 0);
  const meta = await page.evaluate(() => {
    const s = window.nldf.state();
    const c = document.getElementById('canvas');
    return { track: s.track, width: c.width, height: c.height };
  });
  Object.assign(result, meta);

  const b64 = (rgb) => Buffer.from(rgb, 'base64');
  // Full frames: skipping off.
  if (await page.isEnabled('#skip')) await page.uncheck('#skip');
  for (const [p, [yaw, pitch]] of args.poses.entries()) {
    for (const f of args.frames) {
      const rgb = await page.evaluate(async ([f, yaw, pitch]) => {
        const px = await window.nldf.renderFrame(f, yaw, pitch);
        let s = '';
        for (let i = 0; i < px.length; i += 0x8000) s += String.fromCharCode(...px.subarray(i, i + 0x8000));
        return btoa(s);
      }, [f, yaw, pitch]);
      const file = `frame_${f}_${p}.rgb`;
      writeFileSync(path.join(args.out, file), b64(rgb));
      result.frames.push({ frame: f, pose: p, yaw, pitch, file });
    }
  }

  // Dragging on the view turns the head: the sliders follow and the canvas is redrawn.
  const before = await page.evaluate(() => document.getElementById('canvas').toDataURL());
  const box = await page.locator('#drop').boundingBox();
  await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
  await page.mouse.down();
  await page.mouse.move(box.x + box.width / 2 + 60, box.y + box.height / 2 - 30, { steps: 4 });
  await page.mouse.up();
  await page.waitForFunction((b) => document.getElementById('canvas').toDataURL() !== b, before);
  result.drag = await page.evaluate(() => ({
    yaw_deg: Number(document.getElementById('yaw').value),
    pitch_deg: Number(document.getElementById('pitch').value),
  }));
  await page.click('#reset');

  // Skipping on, at the default pose: frames 0 .. N-1 from a fresh skipper, once the live
  // loop has drawn what the box's change asked for.
  if (args.skipFrames > 0) {
    await page.check('#skip');
    await page.waitForFunction(() => window.nldf.state().idle);
    await page.evaluate(() => window.nldf.resetSkipper());
    result.skip = [];
    for (let f = 0; f < args.skipFrames; f++) {
      const out = await page.evaluate(async (f) => {
        const enc = (bytes) => {
          let s = '';
          for (let i = 0; i < bytes.length; i += 0x8000) s += String.fromCharCode(...bytes.subarray(i, i + 0x8000));
          return btoa(s);
        };
        const rgb = await window.nldf.renderFrame(f, 0, 0);
        const last = window.nldf.lastFrame();
        return { rgb: enc(rgb), kind: last.kind, n_rays: last.nRays, head_rays: last.headRays, keep: last.keep && enc(last.keep) };
      }, f);
      const entry = { frame: f, kind: out.kind, n_rays: out.n_rays, head_rays: out.head_rays, file: `skip_${f}.rgb` };
      writeFileSync(path.join(args.out, entry.file), b64(out.rgb));
      if (out.keep) {
        entry.keep = `skip_${f}.keep`;
        writeFileSync(path.join(args.out, entry.keep), b64(out.keep));
      }
      result.skip.push(entry);
    }
  }

  if (args.mic) {
    await page.evaluate(() => window.nldf.startMic());
    const need = (await page.evaluate(() => window.nldf.chunkFor(0).length)) + 16000 / 2;
    await page.waitForFunction((n) => window.nldf.micSamples() >= n, need, { timeout: 20_000 });
    const [yaw, pitch] = args.poses[args.poses.length - 1];
    const mic = await page.evaluate(async ([yaw, pitch]) => {
      const { chunk, rgb } = await window.nldf.micFrame(yaw, pitch);
      const enc = (bytes) => {
        let s = '';
        for (let i = 0; i < bytes.length; i += 0x8000) s += String.fromCharCode(...bytes.subarray(i, i + 0x8000));
        return btoa(s);
      };
      const captured = window.nldf.micSamples();
      await window.nldf.stopMic();
      return { chunk: enc(new Uint8Array(chunk.buffer)), rgb: enc(rgb), captured };
    }, [yaw, pitch]);
    writeFileSync(path.join(args.out, 'mic.f32'), b64(mic.chunk));
    writeFileSync(path.join(args.out, 'mic.rgb'), b64(mic.rgb));
    result.mic = { chunk: 'mic.f32', file: 'mic.rgb', yaw, pitch, captured: mic.captured };
  }

  // The page picks among frame graphs what it can afford: at a target every graph reaches it
  // keeps the one with the most rays, at one none reaches the fastest; then, loaded afresh
  // with no model named, it times the demo's frame graph against 1e9 frames/s and says so.
  if (args.choose) {
    const files = args.choose.map((f) => [readFileSync(f).toString('base64'), path.basename(f)]);
    const picks = [];
    for (const target of [0.001, 1e9]) {
      picks.push(await page.evaluate(async ([files, target]) => {
        const bytes = (b64) => Uint8Array.from(atob(b64), (c) => c.charCodeAt(0));
        const r = await window.nldf.choose(files.map(([b, n]) => [bytes(b), n]), target, 3);
        return { ...r, note: document.getElementById('choice').textContent, model: window.nldf.state().model, width: document.getElementById('canvas').width };
      }, [files, target]));
    }
    result.choice = picks;
    result.errors = await page.evaluate(() => window.nldf.errors.slice());
    await page.goto(`${base}/?autoplay=0&fps=1e9`);
    await page.waitForFunction(() => window.nldf !== undefined);
    await page.evaluate(() => window.nldf.ready);
    result.default_choice = await page.evaluate(() => ({
      model: window.nldf.state().model,
      note: document.getElementById('choice').textContent,
      shown: !document.getElementById('choice').hidden,
    }));
  }

  if (args.screenshot) {
    await page.evaluate(() => window.nldf.play());
    await page.waitForTimeout(1500);
    mkdirSync(path.dirname(args.screenshot), { recursive: true });
    await page.screenshot({ path: args.screenshot });
    await page.evaluate(() => window.nldf.stop());
    result.screenshot = args.screenshot;
  }
  result.errors = (result.errors ?? []).concat(await page.evaluate(() => window.nldf.errors.slice()));
} catch (e) {
  failed = e;
  result.failure = String(e.message ?? e).split('\n')[0];
} finally {
  await context?.close().catch(() => {});
  server.close();
  rmSync(profile, { recursive: true, force: true });
}
writeFileSync(path.join(args.out, 'result.json'), JSON.stringify(result, null, 2));
if (failed) {
  console.error(`browser: ${result.failure}`);
  process.exit(1);
}
console.log(JSON.stringify({ frames: result.frames.length, mic: !!result.mic, errors: result.errors.length + result.page_errors.length + result.console_errors.length }));
