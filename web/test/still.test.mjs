// The page's still-pixel skipper (src/still.js) in node, no browser: the coarse `keep` it
// gives a graph with a learned upsampler. nldf's upsampler_config::receptive_halo and
// FrameRenderer::render_pixels are the reference.
// node --test web/test/still.test.mjs
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { StillSkipper, coarseKeep, receptiveHalo } from '../src/still.js';

test('the halo is nldf receptive_halo: 1 without an upsampler, 2 for x2, x4 and x8', () => {
  assert.deepEqual([1, 2, 4, 8].map(receptiveHalo), [1, 2, 2, 2]);
});

test('a kept pixel keeps its cell and the cells within the halo, inside the grid', () => {
  // 8 x 8 pixels, x2: a 4 x 4 grid. Pixel (x 7, y 0) is cell (row 0, col 3).
  const keep = new Uint8Array(64);
  keep[7] = 1;
  const coarse = coarseKeep(keep, 8, 8, 2);
  assert.equal(coarse.length, 16);
  const cells = [...coarse.keys()].filter((c) => coarse[c]);
  // Rows 0-2, columns 1-3.
  assert.deepEqual(cells, [1, 2, 3, 5, 6, 7, 9, 10, 11]);
  // Two pixels of one cell keep what one does.
  keep[6] = 1;
  keep[15] = 1;
  assert.deepEqual(coarseKeep(keep, 8, 8, 2), coarse);
});

test('an upsampled graph gets the coarse keep, and only the kept pixels change', async () => {
  const [width, height, factor] = [16, 16, 4];
  const config = { threshold: 0.1, margin: 0, refresh: 25, probes: 1 };
  const skipper = new StillSkipper(width, height, config, factor);
  const calls = [];
  // A graph whose pixel 0 follows the audio's first sample; every other pixel shows the
  // audio too where its coarse cell is kept, so that a frame reveals what it was given.
  const run = async (chunk, pose, keep) => {
    calls.push(keep);
    const image = new Float32Array(width * height * 3);
    image.fill(chunk[0], 0, 3);
    if (keep) {
      for (let p = 1; p < width * height; p++) {
        const cell = Math.floor(Math.floor(p / width) / factor) * (width / factor) + Math.floor((p % width) / factor);
        if (keep[cell]) image.fill(chunk[0], 3 * p, 3 * p + 3);
      }
    }
    return { image, nRays: keep ? keep.reduce((a, b) => a + b, 0) : 16 };
  };
  const pose = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1];
  const full = await skipper.render(run, pose, [0], () => [[1]]);
  assert.equal(full.kind, 'full');
  const probed = await skipper.render(run, pose, [0.5], () => [[1]]);
  assert.equal(probed.kind, 'probed');
  // The skipped frame's keep: pixel 0 alone; the graph's: its cell's 3 x 3 of the 4 x 4 grid.
  assert.deepEqual([...probed.keep.keys()].filter((p) => probed.keep[p]), [0]);
  const given = calls.at(-1);
  assert.equal(given.length, 16);
  assert.deepEqual([...given.keys()].filter((c) => given[c]), [0, 1, 2, 4, 5, 6, 8, 9, 10]);
  assert.equal(probed.nRays, 9);
  // Pixel 0 from the graph, every other pixel the full frame's though the graph changed it.
  assert.equal(probed.image[0], 0.5);
  assert.ok(probed.image.slice(3).every((v) => v === 0));
});
