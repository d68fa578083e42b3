#!/usr/bin/env python3
"""The grid teacher against the MLP teacher on the test scenes, from the committed runs.

Reads the runs named in PAIRS (metrics_{val,novel,voice}.json and timing.json; the grid
teacher's written by scripts/grid_demos.sh) and writes results/grid/summary.json: per scene, each teacher's and each student's head, mouth and whole-frame PSNR
per split, the differences the issue asks about (grid minus MLP, student minus its
teacher) and the teacher's time for the student's targets. Prints a table.
"""

import json
import os
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


# Each test scene's pair: the MLP teacher's run and the grid teacher's, relative to
# results/grid/. The MLP recipe is pinned in steps and reproduces bit for bit across
# machines (seed 0 rerun here matched the committed run of results/demo/kept_audio/ in
# every printed figure), so seed 1 and the second head take the committed runs; their
# targets' seconds come from another machine and are not compared.
PAIRS = {
    "s0": ("epyc_s0_mlp", "epyc_s0_grid", True),
    "s1": ("../demo/kept_audio/xeon_s1", "epyc_s1_grid", False),
    "h2": ("../demo/kept_audio/xeon_head2", "epyc_h2_grid", False),
}


def main():
    summary = []
    for scene, (mlp, grid, same_machine) in PAIRS.items():
        dirs = {"mlp": os.path.join(ROOT, mlp), "grid": os.path.join(ROOT, grid)}
        if not all(os.path.isdir(d) for d in dirs.values()):
            continue
        r = {t: run_figures(d) for t, d in dirs.items()}
        # The run folders, from the repository's root.
        sources = {t: os.path.normpath(os.path.join("results", "grid", d)) + "/"
                   for t, d in (("mlp", mlp), ("grid", grid))}
        entry = {"scene": scene, "sources": sources, "runs": r}
        g, m = r["grid"]["models"], r["mlp"]["models"]
        entry["grid_minus_mlp"] = {
            "teacher": diff(g["teacher"], m["teacher"]),
            "student": diff(g["student"], m["student"]),
        }
        entry["student_minus_teacher"] = {
            t: diff(r[t]["models"]["student"], r[t]["models"]["teacher"]) for t in ("mlp", "grid")
        }
        if same_machine:
            entry["targets_s_ratio"] = r["grid"]["targets_s"] / r["mlp"]["targets_s"]
        summary.append(entry)
    with open(os.path.join(ROOT, "summary.json"), "w") as f:
        json.dump({"scenes": summary}, f, indent=2)
    for e in summary:
        print(f"{e['scene']}:")
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
        if "targets_s_ratio" in e:
            print(f"  targets: grid {e['runs']['grid']['targets_s']:.1f} s, "
                  f"mlp {e['runs']['mlp']['targets_s']:.1f} s (same machine)")


if __name__ == "__main__":
    sys.exit(main())
