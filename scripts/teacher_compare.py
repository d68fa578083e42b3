#!/usr/bin/env python3
"""Teachers compared at equal wall time on one scene.

Trains the demo's MLP teacher (its recipe, pinned in steps) and then each variant named in
a variants file for as many training seconds as the MLP teacher took on this machine, one
after another (never two at once, so that each has both cores), and scores each with
`nldf eval` on the splits asked for. Writes one JSON of every run's configuration, seconds,
steps and scores.

    python3 scripts/teacher_compare.py --nldf target/release/nldf --data DATA \\
        --work WORK --variants VARIANTS.json --out OUT.json [--splits val,novel] [--frames 8]

VARIANTS.json maps a name to overrides of the grid preset's run configuration, by dotted
key, e.g. {"grid": {}, "grid_lr3": {"train.lr": 0.003}}; a variant whose "preset" is "small"
starts from the MLP teacher's configuration instead.
"""

import argparse
import copy
import csv
import json
import os
import platform
import subprocess
import sys
import time

# The demo's teacher recipe (train/src/job/recipe.rs): 1100 steps of 1024 rays from 4 frames,
# the learning rate 1e-3 held for 60 % of them, then tenfold down.
RECIPE_TRAIN = {
    "seed": 0,
    "iters": 1100,
    "batch_rays": 1024,
    "frames_per_batch": 4,
    "face_fraction": 0.95,
    "mouth_fraction": 0.1,
    "lr": 1e-3,
    "lr_decay_steps": 440,
    "lr_hold_steps": 660,
    "val_every": 0,
    "val_frames": 4,
    "checkpoint_every": 0,
}

GRID_MODEL = {
    "depth": 2,
    "width": 64,
    "skips": [],
    "color_width": 64,
    "grid": {},
}


def set_dotted(cfg, key, value):
    node = cfg
    parts = key.split(".")
    for p in parts[:-1]:
        node = node.setdefault(p, {})
        if node is None:
            raise SystemExit(f"{key}: {p} is null")
    node[parts[-1]] = value


def run(cmd, log):
    with open(log, "a") as f:
        f.write("$ " + " ".join(cmd) + "\n")
        f.flush()
        r = subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT)
    if r.returncode != 0:
        raise SystemExit(f"failed ({r.returncode}): {' '.join(cmd)}; see {log}")


def trained_seconds(run_dir):
    """Training seconds and steps from the teacher's log.csv (its last row)."""
    path = os.path.join(run_dir, "teacher", "log.csv")
    with open(path) as f:
        rows = list(csv.DictReader(f))
    last = rows[-1]
    return float(last["elapsed_s"]), int(last["step"])


def scores(nldf, run_dir, data, split, frames, log):
    out = os.path.join(run_dir, "eval", split)
    run([nldf, "eval", "--run", run_dir, "--data", data, "--split", split,
         "--frames", str(frames), "--out", out], log)
    with open(os.path.join(out, "metrics.json")) as f:
        m = json.load(f)
    t = next(x for x in m["models"] if x["label"] == "teacher")
    return {k: t[k] for k in ("psnr", "head_psnr", "mouth_psnr", "ssim", "render_s_per_frame")}


def train(nldf, data, run_dir, cfg, log):
    os.makedirs(run_dir, exist_ok=True)
    path = os.path.join(run_dir, "teacher_config.json")
    with open(path, "w") as f:
        json.dump(cfg, f, indent=2)
    started = time.time()
    run([nldf, "train", "teacher", "--data", data, "--run", run_dir, "--config", path], log)
    return time.time() - started


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1])
    ap.add_argument("--nldf", required=True)
    ap.add_argument("--data", required=True)
    ap.add_argument("--work", required=True)
    ap.add_argument("--variants", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--splits", default="val,novel")
    ap.add_argument("--frames", type=int, default=8)
    ap.add_argument("--budget", type=float, default=0.0,
                    help="training seconds for the variants; without it the MLP teacher is trained "
                         "first and its seconds are the budget")
    a = ap.parse_args()
    with open(a.variants) as f:
        variants = json.load(f)
    os.makedirs(a.work, exist_ok=True)
    log = os.path.join(a.work, "compare.log")
    splits = a.splits.split(",")
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    cpu = ""
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next(l.split(":", 1)[1].strip() for l in f if l.startswith("model name"))
    except (OSError, StopIteration):
        cpu = platform.processor()
    result = {"commit": commit, "cpu": cpu, "threads": os.cpu_count(), "data": a.data,
              "splits": splits, "frames": a.frames, "runs": []}

    budget = a.budget
    if budget <= 0:
        mlp_dir = os.path.join(a.work, "mlp")
        mlp_cfg = {"model": {}, "train": copy.deepcopy(RECIPE_TRAIN)}
        # The small preset is the model's default.
        wall = train(a.nldf, a.data, mlp_dir, mlp_cfg, log)
        secs, steps = trained_seconds(mlp_dir)
        budget = secs
        entry = {"name": "mlp", "config": mlp_cfg, "train_s": secs, "wall_s": wall,
                 "steps": steps}
        entry.update({s: scores(a.nldf, mlp_dir, a.data, s, a.frames, log) for s in splits})
        result["runs"].append(entry)
        print(json.dumps(entry), flush=True)
    result["budget_s"] = budget

    for name, overrides in variants.items():
        overrides = dict(overrides)
        preset = overrides.pop("preset", "grid")
        cfg = {"model": copy.deepcopy(GRID_MODEL) if preset == "grid" else {},
               "train": copy.deepcopy(RECIPE_TRAIN)}
        cfg["train"].update({"iters": 10_000_000, "lr_hold_steps": 0,
                             "lr_decay_steps": 1_000_000_000, "time_budget_s": budget})
        for k, v in overrides.items():
            set_dotted(cfg, k, v)
        d = os.path.join(a.work, name)
        wall = train(a.nldf, a.data, d, cfg, log)
        secs, steps = trained_seconds(d)
        entry = {"name": name, "config": cfg, "train_s": secs, "wall_s": wall, "steps": steps}
        entry.update({s: scores(a.nldf, d, a.data, s, a.frames, log) for s in splits})
        result["runs"].append(entry)
        print(json.dumps(entry), flush=True)
        with open(a.out, "w") as f:
            json.dump(result, f, indent=2)
    with open(a.out, "w") as f:
        json.dump(result, f, indent=2)


if __name__ == "__main__":
    sys.exit(main())
