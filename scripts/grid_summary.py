#!/usr/bin/env python3
"""The grid teacher against the MLP teacher on the test scenes, from the committed runs.

Reads results/grid/<machine>_<scene>_<teacher>/ (metrics_{val,novel,voice}.json, timing.json,
teacher_config.json, written by scripts/grid_demos.sh) and writes results/grid/summary.json:
per machine and scene, each teacher's and each student's head, mouth and whole-frame PSNR
per split, the differences the issue asks about (grid minus MLP, student minus its
teacher) and the teacher's time for the student's targets. Prints a table.
"""

import json
import os
import re
import sys

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "results", "grid")
SPLITS = ("val", "novel", "voice")
METRICS = ("head_psnr", "mouth_psnr", "psnr")


def load(path):
    with open(path) as f:
        return json.load(f)


def run_figures(d):
    out = {"models": {}}
    for split in SPLITS:
        m = load(os.path.join(d, f"metrics_{split}.json"))
        for model in m["models"]:
            label = model["label"]
            if label not in ("teacher", "student"):
                continue
            out["models"].setdefault(label, {})[split] = {k: model[k] for k in METRICS}
    parts = {p["what"]: p for p in load(os.path.join(d, "timing.json"))["parts"]}
    targets = [p for w, p in parts.items() if w.startswith("student: teacher targets")]
    out["targets_s"] = sum(p["seconds"] for p in targets)
    steps = parts.get("teacher: training steps", {})
    out["teacher_train_s"] = steps.get("seconds")
    out["teacher_steps"] = steps.get("count")
    return out


def diff(a, b):
    return {s: {k: a[s][k] - b[s][k] for k in METRICS} for s in SPLITS}


def main():
    runs = {}
    for name in sorted(os.listdir(ROOT)):
        m = re.fullmatch(r"(.+)_(s\d+|h2)_(mlp|grid)", name)
        if m and os.path.isdir(os.path.join(ROOT, name)):
            runs.setdefault((m.group(1), m.group(2)), {})[m.group(3)] = run_figures(
                os.path.join(ROOT, name))
    summary = []
    for (machine, scene), r in sorted(runs.items()):
        entry = {"machine": machine, "scene": scene, "runs": r}
        if "mlp" in r and "grid" in r:
            g, m = r["grid"]["models"], r["mlp"]["models"]
            entry["grid_minus_mlp"] = {
                "teacher": diff(g["teacher"], m["teacher"]),
                "student": diff(g["student"], m["student"]),
            }
            entry["student_minus_teacher"] = {
                t: diff(r[t]["models"]["student"], r[t]["models"]["teacher"])
                for t in ("mlp", "grid")
            }
            entry["targets_s_ratio"] = r["grid"]["targets_s"] / r["mlp"]["targets_s"]
        summary.append(entry)
    with open(os.path.join(ROOT, "summary.json"), "w") as f:
        json.dump({"scenes": summary}, f, indent=2)
    for e in summary:
        if "grid_minus_mlp" not in e:
            continue
        print(f"{e['machine']} {e['scene']}:")
        for who in ("teacher", "student"):
            for t in ("mlp", "grid"):
                row = e["runs"][t]["models"][who]
                print(f"  {t:4} {who:7}", " ".join(
                    f"{s} {row[s]['head_psnr']:.2f}/{row[s]['mouth_psnr']:.2f}" for s in SPLITS))
        for who in ("teacher", "student"):
            d = e["grid_minus_mlp"][who]
            print(f"  grid-mlp {who:7}", " ".join(f"{s} {d[s]['head_psnr']:+.2f}" for s in SPLITS))
        for t in ("mlp", "grid"):
            d = e["student_minus_teacher"][t]
            print(f"  student-teacher {t:4}", " ".join(f"{s} {d[s]['head_psnr']:+.2f}" for s in SPLITS))
        print(f"  targets: grid {e['runs']['grid']['targets_s']:.1f} s, mlp {e['runs']['mlp']['targets_s']:.1f} s")


if __name__ == "__main__":
    sys.exit(main())
