#!/usr/bin/env python3
"""The grid teacher with and without its occupancy grid, at the recipe's 2400 steps.

    python3 scripts/grid_occupancy.py --collect RUNS   # then, or alone:
    python3 scripts/grid_occupancy.py
    python3 scripts/grid_occupancy.py --step-cost WORK --nldf NLDF --data DATA --config CFG

With --step-cost, trains the grid teacher of CFG (a run configuration) for 400 steps
without and with an occupancy grid updated from step 0, alternately, three times each, one
process at a time, and writes each run's training seconds to
results/grid/occupancy/step_cost.json with the machine and the commit.

With --collect, copies each run RUNS/o7_<variant> (a grid teacher trained by `nldf train
teacher --config` and scored by `nldf eval` on every frame of val, novel and voice) into
results/grid/occupancy/steps2400/<variant>/: its metrics (machine paths made relative), its
config and, for a teacher with an occupancy grid, the share of the cells that are occupied
at the end (the rule of train/src/networks/occupancy.rs, OccupancyMask::from_density).
Then writes results/grid/occupancy/steps2400/summary.json: each variant's teacher head and
mouth PSNR per split, and its difference from `base` (the recipe's grid teacher) of the same
seed (`_seed1`: the teachers' seed 1).
"""

import argparse
import json
import math
import os
import re
import struct
import sys

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "results", "grid",
                    "occupancy", "steps2400")
SPLITS = ("val", "novel", "voice")
VARIANTS = ("base", "occ", "occw1000", "occt001", "base_seed1", "occt001_seed1",
            "occw1000_seed1")


def load(path):
    with open(path) as f:
        return json.load(f)


def occupied_share(model_path, cfg):
    """Share of the cells occupied after one cell of dilation, as the teacher samples them."""
    with open(model_path, "rb") as f:
        raw = f.read()
    n = struct.unpack("<Q", raw[:8])[0]
    header = json.loads(raw[8:8 + n])
    lo_off, hi_off = header["occupancy.density"]["data_offsets"]
    body = raw[8 + n + lo_off:8 + n + hi_off]
    density = struct.unpack(f"<{len(body) // 4}f", body)
    r = round(len(density) ** (1 / 3))
    grid, occ = cfg["model"]["grid"], cfg["model"]["occupancy"]
    cell = sum((grid["hi"][a] - grid["lo"][a]) / r for a in range(3)) / 3
    threshold = -math.log(1 - occ["min_opacity"]) / cell
    measured = [d for d in density if d >= 0]
    if measured:
        threshold = min(threshold, sum(measured) / len(measured))
    seed = [d < 0 or d >= threshold for d in density]
    occupied = [False] * len(seed)
    for z in range(r):
        for y in range(r):
            for x in range(r):
                if not seed[(z * r + y) * r + x]:
                    continue
                for zz in range(max(z - 1, 0), min(z + 2, r)):
                    for yy in range(max(y - 1, 0), min(y + 2, r)):
                        for xx in range(max(x - 1, 0), min(x + 2, r)):
                            occupied[(zz * r + yy) * r + xx] = True
    return {"resolution": r, "seed_share": sum(seed) / len(seed),
            "occupied_share": sum(occupied) / len(occupied)}


def collect(runs):
    for v in VARIANTS:
        src = os.path.join(runs, f"o7_{v}")
        dst = os.path.join(ROOT, v)
        os.makedirs(dst, exist_ok=True)
        for split in SPLITS:
            with open(os.path.join(src, "eval", split, "metrics.json")) as f:
                text = re.sub(r"/[^\"]*/runs/", "runs/", f.read())
            with open(os.path.join(dst, f"metrics_{split}.json"), "w") as f:
                f.write(text)
        cfg = load(os.path.join(src, "teacher", "config.json"))
        with open(os.path.join(dst, "teacher_config.json"), "w") as f:
            json.dump(cfg, f, indent=2)
        if cfg["model"].get("occupancy"):
            share = occupied_share(os.path.join(src, "teacher", "model.safetensors"), cfg)
            with open(os.path.join(dst, "occupancy.json"), "w") as f:
                json.dump(share, f, indent=2)


def step_cost(work, nldf, data, config):
    import copy
    import csv
    import platform
    import subprocess
    base = load(config)
    base["model"]["occupancy"] = None
    base["train"].update({"iters": 400, "val_every": 0, "checkpoint_every": 0})
    occ = copy.deepcopy(base)
    occ["model"]["occupancy"] = {"warmup_steps": 0}
    cpu = platform.processor()
    with open("/proc/cpuinfo") as f:
        cpu = next((l.split(":", 1)[1].strip() for l in f if l.startswith("model name")), cpu)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    out = {"commit": commit, "cpu": cpu, "threads": os.cpu_count(), "steps": 400,
           "what": "the grid teacher's first 400 steps on the tuning scene, without and with "
                   "an occupancy grid updated from step 0 every 16 steps, alternately",
           "runs": []}
    for i in range(3):
        for name, cfg in (("none", base), ("occupancy", occ)):
            d = os.path.join(work, f"{name}_{i}")
            os.makedirs(d, exist_ok=True)
            path = os.path.join(d, "config.json")
            with open(path, "w") as f:
                json.dump(cfg, f, indent=2)
            subprocess.run([nldf, "train", "teacher", "--data", data, "--run", d, "--config",
                            path], check=True, stdout=subprocess.DEVNULL,
                           stderr=subprocess.DEVNULL)
            with open(os.path.join(d, "teacher", "log.csv")) as f:
                last = list(csv.DictReader(f))[-1]
            out["runs"].append({"variant": name, "seconds": float(last["elapsed_s"])})
            print(out["runs"][-1], flush=True)
    for name in ("none", "occupancy"):
        secs = [r["seconds"] for r in out["runs"] if r["variant"] == name]
        out[f"{name}_mean_s"] = sum(secs) / len(secs)
    out["occupancy_over_none"] = out["occupancy_mean_s"] / out["none_mean_s"]
    with open(os.path.join(ROOT, "..", "step_cost.json"), "w") as f:
        json.dump(out, f, indent=2)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1])
    ap.add_argument("--collect", help="folder holding the o7_<variant> runs")
    ap.add_argument("--step-cost", help="work folder for the step-cost runs")
    ap.add_argument("--nldf", default="target/release/nldf")
    ap.add_argument("--data")
    ap.add_argument("--config")
    a = ap.parse_args()
    if a.step_cost:
        step_cost(a.step_cost, a.nldf, a.data, a.config)
        return
    if a.collect:
        collect(a.collect)
    out = {"scene": "nldf synth --seed 7 (the tuning scene)", "steps": 2400, "variants": {}}
    for v in VARIANTS:
        row = {}
        for split in SPLITS:
            m = load(os.path.join(ROOT, v, f"metrics_{split}.json"))
            t = next(x for x in m["models"] if x["label"] == "teacher")
            row[split] = {k: t[k] for k in ("head_psnr", "mouth_psnr")}
        share = os.path.join(ROOT, v, "occupancy.json")
        if os.path.exists(share):
            row["occupied_percent"] = 100 * load(share)["occupied_share"]
        out["variants"][v] = row
    for v, row in out["variants"].items():
        # Each seed's runs against that seed's teacher without the grid.
        base = out["variants"]["base_seed1" if v.endswith("_seed1") else "base"]
        for split in SPLITS:
            for k in ("head_psnr", "mouth_psnr"):
                row[split][f"{k}_minus_base"] = row[split][k] - base[split][k]
        print(v, " ".join(f"{s} {row[s]['head_psnr']:.2f} ({row[s]['head_psnr_minus_base']:+.2f})"
                          for s in SPLITS))
    seeds = out["variants"]
    out["base_minus_base_seed1"] = {
        split: seeds["base"][split]["head_psnr"] - seeds["base_seed1"][split]["head_psnr"]
        for split in SPLITS}
    with open(os.path.join(ROOT, "summary.json"), "w") as f:
        json.dump(out, f, indent=2)


if __name__ == "__main__":
    sys.exit(main())
