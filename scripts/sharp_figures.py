"""The 512 x 512 figures of docs/sharp.md from `nldf bench upsampler`'s renders (PIL only).

usage: sharp_figures.py BENCH512 DATA512 EVAL128 OUT_GRID OUT_STRIP (PNG; docs/ holds them as JPEG, quality 90)

BENCH512: `nldf bench upsampler`'s output folder for a 512 run (val/, novel/, voice/ with
the teacher's, the native rays', the upsampler's and the bilinear renders); DATA512: its
dataset; EVAL128: the 128 x 128 run's evaluations of the same scene (`nldf eval`, same
frames), whose student is shown upscaled 4x bilinearly. The grid: one frame of each split,
the head at full size; the strip: the mouth over eight voice frames, ground truth, the
upsampler and the 128 model upscaled, top to bottom.
"""
import json
import sys

from PIL import Image, ImageDraw

eval512, data512, eval128, out_grid, out_strip = sys.argv[1:6]
BOX = (112, 96, 400, 448)  # the head at 512 x 512 (x0, y0, x1, y1)


def ids(split):
    m = json.load(open(f"{eval512}/{split}/metrics.json"))
    return [f["img_id"] for f in m["models"][0]["frames"]]


def load(split, label, img_id):
    if label == "truth":
        return Image.open(f"{data512}/head_imgs/{img_id}.png").convert("RGB")
    if label == "128":
        small = Image.open(f"{eval128}/{split}/student/{img_id}.png").convert("RGB")
        return small.resize((512, 512), Image.BILINEAR)
    return Image.open(f"{eval512}/{split}/{label}/{img_id}.png").convert("RGB")


def titled(tiles, titles, pad=4, head=22):
    w, h = tiles[0][0].size
    rows, cols = len(tiles), len(tiles[0])
    out = Image.new("RGB", (cols * (w + pad) - pad, head + rows * (h + pad) - pad), "white")
    draw = ImageDraw.Draw(out)
    for c, t in enumerate(titles):
        draw.text((c * (w + pad) + 4, 4), t, fill="black")
    for r, row in enumerate(tiles):
        for c, tile in enumerate(row):
            out.paste(tile, (c * (w + pad), head + r * (h + pad)))
    return out


columns = [
    ("truth", "ground truth 512"),
    ("teacher", "teacher 512"),
    ("student.fp32.ort", "student, rays at 512"),
    ("upsampler.fp32.ort", "student 128 grid + upsampler"),
    ("student.fp32.ort.up4", "student 128 grid, bilinear"),
    ("128", "shipped 128 model, bilinear"),
]
picks = [("val", 4), ("novel", 2), ("voice", 5)]
rows = []
for split, k in picks:
    img_id = ids(split)[k]
    rows.append([load(split, label, img_id).crop(BOX) for label, _ in columns])
titled(rows, [t for _, t in columns]).save(out_grid)

# The strip: the mouth over consecutive voice frames, three ways.
MOUTH = (176, 304, 336, 400)
frames = ids("voice")[:8]
strip = []
for label in ["truth", "upsampler.fp32.ort", "128"]:
    strip.append([load("voice", label, i).crop(MOUTH) for i in frames])
titled(strip, [f"voice frame {i}" for i in frames]).save(out_strip)
print("wrote", out_grid, out_strip)
