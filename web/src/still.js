// Skipping the pixels the audio does not move, as nldf's StillSkipper (infer/src/still.rs)
// does for `nldf render --skip-still`: while the pose holds still, most of the head keeps
// its colour whatever the audio. A full frame is rendered whenever the pose changes and
// every `refresh` frames at a still pose. On a still pose's second frame the graph renders
// every pixel with the audio of `probes` frames spread over the clip; a pixel whose colour
// over those and the last full frame spreads by more than `threshold` in any channel, grown
// by `margin` pixels (a square), is kept: from then on the graph runs with `keep` = that
// set, and every other pixel is the last full frame's.
//
// A graph with a learned upsampler x`factor` takes `keep` on its coarse grid: the cells of
// the kept pixels, grown by the upsampler's receptive halo (`coarseKeep`), as nldf's
// `FrameRenderer::render_pixels` sends them. The CNN then runs on the box around those
// cells, which gives the kept pixels as the whole frame does; only the kept pixels are
// taken from it.

// SkipConfig::default().
export const SKIP_CONFIG = { threshold: 12 / 255, margin: 2, refresh: 25, probes: 8 };

// still::probe_frames: `k` of `nFrames` frames, the middle of each of `k` equal stretches.
export function probeFrames(nFrames, k) {
  const n = Math.min(k, nFrames);
  const out = [];
  for (let i = 0; i < n; i++) {
    out.push(Math.min(Math.floor(((2 * i + 1) * nFrames) / (2 * n)), Math.max(0, nFrames - 1)));
  }
  return out;
}

// The pixels of a `width` x `height` image within `margin` (a square) of a pixel of `hot`,
// as a 0/1 mask.
export function grow(hot, width, height, margin) {
  const keep = new Uint8Array(width * height);
  for (let j = 0; j < height; j++) {
    for (let i = 0; i < width; i++) {
      if (!hot[j * width + i]) continue;
      for (let y = Math.max(0, j - margin); y <= Math.min(height - 1, j + margin); y++) {
        for (let x = Math.max(0, i - margin); x <= Math.min(width - 1, i + margin); x++) {
          keep[y * width + x] = 1;
        }
      }
    }
  }
  return keep;
}

// upsampler_config::receptive_halo: the coarse cells on each side of an output pixel's own
// cell that an upsampler x`factor` reads for it (2 for x2, x4 and x8).
export function receptiveHalo(factor) {
  const f = Math.max(1, factor);
  let stages = 0;
  while (f % 2 ** (stages + 1) === 0) stages += 1;
  let halo = 1;
  for (let x = 0; x < f; x++) {
    let lo = x - 1;
    let hi = x + 1;
    for (let s = 0; s < stages; s++) {
      lo = Math.floor(lo / 2) - 1;
      hi = Math.floor(hi / 2) + 1;
    }
    halo = Math.max(halo, -lo, hi);
  }
  return halo;
}

// The coarse `keep` of an upsampler x`factor` for the pixels `keep` (0/1, `width` x
// `height`): every cell holding a kept pixel, grown by `receptiveHalo(factor)` cells (a
// square) within the grid.
export function coarseKeep(keep, width, height, factor) {
  const wc = width / factor;
  const hc = height / factor;
  const own = new Uint8Array(wc * hc);
  for (let p = 0, n = width * height; p < n; p++) {
    if (keep[p]) own[Math.floor(Math.floor(p / width) / factor) * wc + Math.floor((p % width) / factor)] = 1;
  }
  return grow(own, wc, hc, receptiveHalo(factor));
}

const samePose = (a, b) => a.length === b.length && a.every((v, i) => v === b[i]);

// Renders frames through `run(chunk, pose, keep)`, which resolves to the graph's
// { image: Float32Array [h w 3], nRays } (keep null: every pixel; else the graph's own
// `keep`, on the coarse grid of an upsampler x`factor`).
export class StillSkipper {
  constructor(width, height, config = SKIP_CONFIG, factor = 1) {
    this.width = width;
    this.height = height;
    this.config = config;
    this.factor = factor;
    this.reset();
  }

  reset() {
    this.pose = null; // the last full frame's pose and image, and its head rays
    this.base = null;
    this.headRays = 0;
    this.keep = null; // the kept pixels at `pose`, once found
    this.runKeep = null; // the graph's `keep` for them
    this.sinceFull = 0;
  }

  // The frame seen from `pose` with the audio `chunk`: { image, kind ('full', 'probed' or
  // 'partial'), nRays (rays this frame's audio went through the student for, the probes'
  // not counted), headRays (the last full frame's), keep (the mask, null for full frames) }.
  // `probeChunks()` gives the probes' audio chunks.
  async render(run, pose, chunk, probeChunks) {
    const still = this.pose !== null && samePose(this.pose, pose);
    if (!still || this.sinceFull >= this.config.refresh) {
      const out = await run(chunk, pose, null);
      if (!still) this.keep = null;
      this.pose = Array.from(pose);
      this.base = out.image;
      this.headRays = out.nRays;
      this.sinceFull = 1;
      return { image: out.image, kind: 'full', nRays: out.nRays, headRays: out.nRays, keep: null };
    }
    let kind = 'partial';
    if (this.keep === null) {
      this.keep = await this.findMoving(run, pose, probeChunks());
      this.runKeep = this.factor > 1 ? coarseKeep(this.keep, this.width, this.height, this.factor) : this.keep;
      kind = 'probed';
    }
    this.sinceFull += 1;
    const image = this.base.slice();
    let nRays = 0;
    if (this.keep.some((k) => k)) {
      const out = await run(chunk, pose, this.runKeep);
      nRays = out.nRays;
      for (let p = 0, n = this.width * this.height; p < n; p++) {
        if (!this.keep[p]) continue;
        for (let c = 0; c < 3; c++) image[3 * p + c] = out.image[3 * p + c];
      }
    }
    return { image, kind, nRays, headRays: this.headRays, keep: this.keep };
  }

  // The pixels whose colour over the probes and the last full frame spreads by more than
  // the threshold, grown by the margin (f32 arithmetic, as nldf's).
  async findMoving(run, pose, chunks) {
    const lo = Float32Array.from(this.base);
    const hi = Float32Array.from(this.base);
    for (const chunk of chunks) {
      const { image } = await run(chunk, pose, null);
      for (let k = 0; k < image.length; k++) {
        if (image[k] < lo[k]) lo[k] = image[k];
        if (image[k] > hi[k]) hi[k] = image[k];
      }
    }
    const threshold = Math.fround(this.config.threshold);
    const n = this.width * this.height;
    const hot = new Uint8Array(n);
    for (let p = 0; p < n; p++) {
      for (let c = 0; c < 3; c++) {
        if (Math.fround(hi[3 * p + c] - lo[3 * p + c]) > threshold) hot[p] = 1;
      }
    }
    return grow(hot, this.width, this.height, this.config.margin);
  }
}
