#!/usr/bin/env python3
"""How far a prepared pose track turns against the truth's: for frames 50 apart (every 5th
recorded frame), the rotation between them in the first frame's camera axes, as an angle
about each axis, true and prepared; prints per axis the true spread and the least-squares
slope prepared / true (1 means the prepared track turns as far as the true one).

Usage: scripts/turn_slopes.py TRUTH_DATASET PREPARED_DATASET
"""
import json
import math
import sys


def rotations(d):
    frames = []
    for split in ("train", "val"):
        with open(f"{d}/transforms_{split}.json") as f:
            frames += json.load(f)["frames"]
    return {x["img_id"]: [row[:3] for row in x["transform_matrix"][:3]] for x in frames}


def relative(a, b):
    # a^T b
    return [[sum(a[k][i] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def axis_angle_deg(r):
    c = max(-1.0, min(1.0, (r[0][0] + r[1][1] + r[2][2] - 1) / 2))
    a = math.acos(c)
    if a < 1e-9:
        return [0.0, 0.0, 0.0]
    s = 2 * math.sin(a)
    v = [(r[2][1] - r[1][2]) / s, (r[0][2] - r[2][0]) / s, (r[1][0] - r[0][1]) / s]
    return [math.degrees(x * a) for x in v]


def main():
    truth, prepared = rotations(sys.argv[1]), rotations(sys.argv[2])
    ids = sorted(set(truth) & set(prepared))
    pairs = []
    for i in ids[::5]:
        j = i + 50
        if j in truth and j in prepared:
            pairs.append(
                (
                    axis_angle_deg(relative(truth[i], truth[j])),
                    axis_angle_deg(relative(prepared[i], prepared[j])),
                )
            )
    for k, name in enumerate(["x (pitch)", "y (yaw)", "z (roll)"]):
        t = [p[0][k] for p in pairs]
        q = [p[1][k] for p in pairs]
        mean = sum(t) / len(t)
        spread = math.sqrt(sum((x - mean) ** 2 for x in t) / len(t))
        slope = sum(a * b for a, b in zip(t, q)) / sum(a * a for a in t)
        print(f"{name}: true spread {spread:.2f} deg, prepared / true slope {slope:.3f}")


if __name__ == "__main__":
    main()
