#!/usr/bin/env python3
"""Writes results/demo/differences.json: the differences that docs/demo.md's bar tables
print (student minus teacher per scene and split, a second student seed minus its teacher,
the distilled student minus the pixels-only one), each computed from the runs' committed
metrics_{val,novel,voice}.json as the pages print them: the difference of the two figures
rounded to the printed precision (2 decimals for PSNR, 1 for the repainted percentage).

Usage: scripts/derived_figures.py   (from the repository's root)
"""

import json
import os

SPLITS = ["val", "novel", "voice"]
SCENES = ["xeon_s0", "xeon_s1", "xeon_head2"]


def models(folder, split):
    path = os.path.join(folder, f"metrics_{split}.json")
    return json.load(open(path))["models"]


def printed(m):
    return {
        "head": round(m["head_psnr"], 2),
        "mouth": round(m["mouth_psnr"], 2),
        "repainted": round(100 * m["repainted"], 1),
    }


def minus(a, b):
    return {k: round(a[k] - b[k], 1 if k == "repainted" else 2) for k in a}


def student_minus_teacher(folder, student_label=None):
    out = {}
    for split in SPLITS:
        ms = models(folder, split)
        teacher = next(m for m in ms if m["label"] == "teacher")
        student = next(
            m for m in ms if m["label"] != "teacher" and student_label in (None, m["label"])
        )
        out[split] = minus(printed(student), printed(teacher))
    return out


def main():
    root = "results/demo"
    out = {
        "note": "differences of printed figures (2 decimals for PSNR, 1 for the repainted percentage) "
        "from each run's metrics_{val,novel,voice}.json; written by scripts/derived_figures.py",
        "now": {s: student_minus_teacher(f"{root}/kept_audio/{s}", "student") for s in SCENES},
        "before": {s: student_minus_teacher(f"{root}/{s}", "student") for s in SCENES},
        "second_seed": {
            "xeon_s0": student_minus_teacher(f"{root}/xeon_s0/audio_fixed_seed1"),
            "xeon_s1": student_minus_teacher(f"{root}/kept_audio/xeon_s1/student_seed1"),
            "xeon_head2": student_minus_teacher(f"{root}/kept_audio/xeon_head2/student_seed1"),
        },
    }
    # Now: both students of the equal-minutes runs; before: the former headline student
    # against the former pixels-only student (5000 steps).
    margins = {}
    for name, distilled, pixels_only in [
        ("now", f"{root}/epyc_s0_equal_minutes/distilled", f"{root}/epyc_s0_equal_minutes/pixels_only"),
        ("before", f"{root}/xeon_s0", f"{root}/xeon_s0/pixels_only"),
    ]:
        student = next(m for m in models(distilled, "novel") if m["label"] == "student")
        pixels = next(m for m in models(pixels_only, "novel") if m["label"] != "teacher")
        margins[name] = minus(printed(student), printed(pixels))["head"]
    out["distilled_minus_pixels_only_novel_head"] = margins
    path = f"{root}/differences.json"
    with open(path + ".tmp", "w") as f:
        json.dump(out, f, indent=1)
        f.write("\n")
    os.replace(path + ".tmp", path)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
