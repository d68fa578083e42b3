// Skipping the pixels the audio does not move, as nldf's StillSkipper (infer/src/still.rs)
// does for `nldf render --skip-still`: while the pose holds still, most of the head keeps
// its colour whatever the audio. A full frame is rendered whenever the pose changes and
// every `refresh` frames at a still pose. On a still pose's second frame the graph renders
// every pixel with the audio of `probes` frames spread over the clip; a pixel whose colour
// over those and the last full frame spreads by more than `threshold` in any channel, grown
// by `margin` pixels (a square), is kept: from then on the graph runs with `keep` = that
// set, and every other pixel is the last full frame's.

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

const samePose = (a, b) => a.length === b.length && a.every((v, i) => v === b[i]);

// Renders frames through `run(chunk, pose, keep)`, which resolves to the graph's
// { image: Float32Array [h w 3], nRays } (keep null: every pixel).
export class StillSkipper {
  constructor(width, height, config = SKIP_CONFIG) {
    this.width = width;
    this.height = height;
    this.config = config;
    this.reset();
  }

  reset() {
    this.pose = null; // the last full frame's pose and image, and its head rays
    this.base = null;
    this.headRays = 0;
    this.keep = null; // the kept pixels at `pose`, once found
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
      kind = 'probed';
    }
    this.sinceFull += 1;
    const image = this.base.slice();
    let nRays = 0;
    if (this.keep.some((k) => k)) {
      const out = await run(chunk, pose, this.keep);
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
