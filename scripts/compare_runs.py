#!/usr/bin/env python3
"""Compares two runs of `nldf demo` on the same scene: the weights of each checkpoint (a
SHA-256 of the tensors of teacher/ and student/ model.safetensors, without the metadata that
records wall-clock seconds) and every score of metrics_{val,novel,voice}.json
(head, whole-frame and mouth PSNR, SSIM, the repainted share), writing the values of both
runs and their differences as JSON.

Usage: scripts/compare_runs.py NAME_A RUN_A NAME_B RUN_B OUT.json
  RUN is a run folder (as `nldf demo --out` writes) or a folder holding its results files
  (metrics_*.json, and checksums.json written by this script with --checksums RUN OUT);
  checkpoints are compared where both runs have them.
"""

import hashlib
import json
import os
import struct
import sys

SCORES = ["head_psnr", "psnr", "mouth_psnr", "head_ssim", "ssim", "repainted"]


def weights_digest(path):
    """SHA-256 of a safetensors file's tensors (names, shapes, dtypes and bytes), without its
    metadata, which records the run's wall-clock seconds."""
    blob = open(path, "rb").read()
    n = struct.unpack("<Q", blob[:8])[0]
    header = json.loads(blob[8 : 8 + n])
    header.pop("__metadata__", None)
    digest = hashlib.sha256(json.dumps(header, sort_keys=True).encode())
    digest.update(blob[8 + n :])
    return digest.hexdigest()


def checksums(run):
    """The weights' digests of the run's checkpoints, or those recorded in its
    checksums.json."""
    recorded = os.path.join(run, "checksums.json")
    if os.path.exists(recorded):
        return json.load(open(recorded))
    out = {}
    for stage in ["teacher", "student"]:
        path = os.path.join(run, stage, "model.safetensors")
        if os.path.exists(path):
            out[stage] = weights_digest(path)
    return out


def metrics(run, split):
    for path in [os.path.join(run, f"metrics_{split}.json"), os.path.join(run, "eval", split, "metrics.json")]:
        if os.path.exists(path):
            return {m["label"]: m for m in json.load(open(path))["models"]}
    raise SystemExit(f"{run}: no metrics_{split}.json")


def main():
    if len(sys.argv) == 4 and sys.argv[1] == "--checksums":
        json.dump(checksums(sys.argv[2]), open(sys.argv[3], "w"), indent=1)
        return
    if len(sys.argv) != 6:
        raise SystemExit(__doc__)
    name_a, run_a, name_b, run_b, out = sys.argv[1:]
    sums = {name_a: checksums(run_a), name_b: checksums(run_b)}
    report = {
        "runs": [name_a, name_b],
        # Only where both runs kept their checkpoints.
        "checkpoints_identical": {
            s: sums[name_a][s] == sums[name_b][s] for s in sums[name_a] if s in sums[name_b]
        },
        "checksums": sums,
        "scores": {},
    }
    largest = 0.0
    for split in ["val", "novel", "voice"]:
        a, b = metrics(run_a, split), metrics(run_b, split)
        for label in a:
            row = {}
            for key in SCORES:
                va, vb = a[label][key], b[label][key]
                row[key] = {name_a: va, name_b: vb, "difference": vb - va}
                largest = max(largest, abs(vb - va))
            report["scores"].setdefault(split, {})[label] = row
    report["largest_absolute_difference"] = largest
    with open(out + ".tmp", "w") as f:
        json.dump(report, f, indent=1)
        f.write("\n")
    os.replace(out + ".tmp", out)
    print(f"wrote {out}: checkpoints identical {report['checkpoints_identical']}, largest difference {largest}")


if __name__ == "__main__":
    main()
