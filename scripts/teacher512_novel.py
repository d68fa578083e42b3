#!/usr/bin/env python3
"""Both teachers at 512 x 512 on `novel`, and whether they are the teachers of the val table.

Reads results/grid/teacher512_epyc/teacher512_{mlp,grid}_metrics_novel.json (`nldf eval
--split novel` on all 84 frames of seed 0 at 512, each teacher trained again with the
configurations in results/grid/h200/) and teacher512_{mlp,grid}_metrics_val3.json (`nldf
eval --split val --frames 3` of the same teachers), and the val scores of the lent
machine's batch in results/grid/h200/. Writes results/grid/teacher512_epyc/summary.json:
per teacher the head and mouth PSNR on `novel` and per kind of view, the grid teacher minus
the MLP teacher, and per teacher the largest difference of a val frame's PSNR from the same
frame in the lent machine's run (0 says the teacher was trained again exactly).
"""

import json
import os

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "results", "grid")
HERE = os.path.join(ROOT, "teacher512_epyc")
METRICS = ("head_psnr", "mouth_psnr")


def load(path):
    with open(path) as f:
        return json.load(f)


def teacher(path):
    return next(m for m in load(path)["models"] if m["label"] == "teacher")


def scores(m):
    out = {k: m[k] for k in METRICS}
    out["frames"] = len(m["frames"])
    # Keyed by the view's first word: `turned` (1.5 times the recording's turn), `closer`,
    # `farther`.
    out["by_view"] = {v["view"].split()[0]: {k: v[k] for k in METRICS} for v in m["by_view"]}
    return out


def main():
    teachers = {}
    again = {}
    for t in ("mlp", "grid"):
        teachers[t] = scores(teacher(os.path.join(HERE, f"teacher512_{t}_metrics_novel.json")))
        then = {f["img_id"]: f for f in
                teacher(os.path.join(ROOT, "h200", f"teacher512_{t}_metrics_val.json"))["frames"]}
        now = teacher(os.path.join(HERE, f"teacher512_{t}_metrics_val3.json"))["frames"]
        again[t] = {
            "frames": [f["img_id"] for f in now],
            "largest_psnr_difference": max(abs(f["psnr"] - then[f["img_id"]]["psnr"]) for f in now),
            "largest_head_psnr_difference":
                max(abs(f["head_psnr"] - then[f["img_id"]]["head_psnr"]) for f in now),
        }
    g, m = teachers["grid"], teachers["mlp"]
    minus = {k: g[k] - m[k] for k in METRICS}
    minus["by_view"] = {v: {k: g["by_view"][v][k] - m["by_view"][v][k] for k in METRICS}
                        for v in g["by_view"]}
    out = {"novel": teachers, "grid_minus_mlp": minus, "val_again_against_h200": again}
    with open(os.path.join(HERE, "summary.json"), "w") as f:
        json.dump(out, f, indent=1)
    for t in ("mlp", "grid"):
        views = " ".join(f"{v} {s['head_psnr']:.2f}/{s['mouth_psnr']:.2f}"
                         for v, s in teachers[t]["by_view"].items())
        print(f"{t:4} novel {teachers[t]['head_psnr']:.2f}/{teachers[t]['mouth_psnr']:.2f}  {views}"
              f"  val again: largest head difference {again[t]['largest_head_psnr_difference']:.3f}")
    print(f"grid - mlp {minus['head_psnr']:+.2f}/{minus['mouth_psnr']:+.2f} " + " ".join(
        f"{v} {s['head_psnr']:+.2f}/{s['mouth_psnr']:+.2f}" for v, s in minus["by_view"].items()))


if __name__ == "__main__":
    main()
