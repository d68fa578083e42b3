#!/usr/bin/env python3
"""A real face for `nldf prepare`: scikit-image's astronaut photo (NASA, public domain; the
wheel carries it) seen by a camera that rolls about its optical axis, which turns the whole
image about its centre, exactly, whatever the scene. The true motion is that roll alone: each
camera turns about its own view axis by the frame's roll and stays where it is.

  photo_roll.py frames PHOTO DIR ROLL_DEG   12 s of 256 x 256 frames, +-ROLL_DEG, two cycles;
                                            DIR/roll.json holds each frame's roll
  photo_roll.py score PREPARED ROLL_JSON    the prepared cameras against the roll, as JSON
  photo_roll.py picture PREPARED OUT.png    three frames' .lms points and parsing

Runs in nldf's face environment (OpenCV, numpy)."""
import json
import math
import os
import sys

import cv2
import numpy as np

# The crop's centre in the photo (the face, its hair and chin inside) and its side; the
# video's principal point is the crop's centre, so the roll turns about it.
CENTRE, SIDE, FRAMES, PERIOD = (225.0, 140.0), 256, 300, 150.0


def frames(photo, out, roll):
    img = cv2.imread(photo)
    os.makedirs(out, exist_ok=True)
    angles = []
    for t in range(FRAMES):
        a = roll * math.sin(2 * math.pi * t / PERIOD)
        m = cv2.getRotationMatrix2D(CENTRE, a, 1.0)
        m[0, 2] += SIDE / 2 - CENTRE[0]
        m[1, 2] += SIDE / 2 - CENTRE[1]
        f = cv2.warpAffine(img, m, (SIDE, SIDE), flags=cv2.INTER_CUBIC,
                           borderMode=cv2.BORDER_REFLECT)
        cv2.imwrite(f"{out}/{t:04d}.png", f)
        angles.append(a)
    with open(f"{out}/roll.json", "w") as fh:
        json.dump({"roll_deg": angles, "fps": 25, "side": SIDE}, fh)


def cameras(prepared):
    entries = []
    for split in ("train", "val"):
        with open(f"{prepared}/transforms_{split}.json") as fh:
            entries += json.load(fh)["frames"]
    return {e["img_id"]: np.array(e["transform_matrix"]) for e in entries}


def rot_z(deg):
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def angle_deg(r):
    return math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(r) - 1.0) / 2.0))))


def score(prepared, roll_json):
    with open(roll_json) as fh:
        roll = json.load(fh)["roll_deg"]
    m = cameras(prepared)
    ids = sorted(m)
    r0 = m[ids[0]][:3, :3]
    # Each camera's rotation from the first, in the first camera's axes (OpenGL: z is the
    # view axis), against the true roll about it; the image's y points down, so the roll's
    # sign in camera axes is fitted, once for the clip.
    true = [roll[i] - roll[ids[0]] for i in ids]
    rel = [r0.T @ m[i][:3, :3] for i in ids]
    errors = {}
    for sign in (1.0, -1.0):
        errors[sign] = [angle_deg(d.T @ rot_z(sign * t)) for d, t in zip(rel, true)]
    sign = min(errors, key=lambda s: np.mean(errors[s]))
    err = errors[sign]
    solved = [sign * math.degrees(math.atan2(d[1, 0], d[0, 0])) for d in rel]
    # What is left besides the roll: the angle of the rotation about the other two axes.
    off_axis = [angle_deg(d @ rot_z(-math.degrees(math.atan2(d[1, 0], d[0, 0])))) for d in rel]
    # The landmarks alone: each frame's .lms against frame 0's turned by the true roll about
    # the image's centre (they would match exactly if the face model followed the roll).
    side = cv2.imread(f"{prepared}/ori_imgs/{ids[0]}.jpg").shape[1]
    lms0 = np.loadtxt(f"{prepared}/ori_imgs/{ids[0]}.lms")
    lms_err = []
    for i, t in zip(ids, true):
        turn = cv2.getRotationMatrix2D((side / 2, side / 2), t, 1.0)
        moved = lms0 @ turn[:, :2].T + turn[:, 2]
        lms_err.append(np.linalg.norm(np.loadtxt(f"{prepared}/ori_imgs/{i}.lms") - moved, axis=1))
    lms_err = np.array(lms_err)
    centres = np.array([m[i][:3, 3] for i in ids])
    distance = float(np.linalg.norm(centres, axis=1).mean())
    spread = np.linalg.norm(centres - centres.mean(0), axis=1) / distance
    out = {
        "frames": len(ids),
        "true_roll_range_deg": float(max(true) - min(true)),
        "rotation_mean_deg": float(np.mean(err)),
        "rotation_worst_deg": float(np.max(err)),
        "roll_slope": float(np.polyfit(true, solved, 1)[0]),
        "off_axis_worst_deg": float(np.max(off_axis)),
        "off_axis_per_roll": float(np.polyfit(np.abs(true), off_axis, 1)[0]),
        "lms_from_turned_first_px": float(lms_err.mean()),
        "lms_jaw_from_turned_first_px": float(lms_err[:, :17].mean()),
        "lms_inner_from_turned_first_px": float(lms_err[:, 17:].mean()),
        "image_side_px": int(side),
        "position_spread_mean": float(spread.mean()),
        "position_spread_worst": float(spread.max()),
    }
    print(json.dumps(out, indent=1))


def picture(prepared, out):
    tiles = []
    for i in (0, 30, 105):
        img = cv2.imread(f"{prepared}/ori_imgs/{i}.jpg")
        parsing = cv2.imread(f"{prepared}/parsing/{i}.png")
        marked = img.copy()
        for x, y in np.loadtxt(f"{prepared}/ori_imgs/{i}.lms"):
            cv2.circle(marked, (int(round(x)), int(round(y))), 1, (0, 255, 0), -1)
        blend = cv2.addWeighted(img, 0.5, parsing, 0.5, 0)
        big = [cv2.resize(t, (256, 256), interpolation=cv2.INTER_NEAREST) for t in (marked, blend)]
        tiles.append(np.vstack(big))
    cv2.imwrite(out, np.hstack(tiles))


if __name__ == "__main__":
    cmd, args = sys.argv[1], sys.argv[2:]
    if cmd == "frames":
        frames(args[0], args[1], float(args[2]))
    elif cmd == "score":
        score(args[0], args[1])
    elif cmd == "picture":
        picture(args[0], args[1])
    else:
        sys.exit(__doc__)
