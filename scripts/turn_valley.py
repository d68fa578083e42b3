#!/usr/bin/env python3
"""Whether a video's feature tracks say how far the head turns: the track bundle (key poses
and track points, Huber loss of 1 px, as `nldf prepare` solves it) started from the true key
poses with every turn scaled by 0.9, 1.0 and 1.1, run to the same number of evaluations.
If the tracks held the turn, every start would end near the true turn (slope 1) and the
starts that end elsewhere would cost more. Writes, per video, the three ends (cost, slopes
of the turn against the truth's) and the prepared dataset's own slopes (its camera track
against the truth, as scripts/turn_slopes.py measures them) to OUT.

The tracks are the face helper's own (`prepare/face/nldf_face.py frames`, run on the
prepared dataset's `ori_imgs/`, so on the frames `nldf prepare` analysed); the true poses and
focal length come from the scene. Run it with the face environment's Python (scipy, cv2,
mediapipe): `~/.cache/nldf/face-env/venv/bin/python scripts/turn_valley.py [--track-reach R]
OUT TRUTH PREPARED [TRUTH PREPARED ...]` where each TRUTH is a test video's scene (say WORK/second_512, made by
scripts/prepare_check.sh) and PREPARED that video prepared at its own size
(WORK/prepared_second_512).
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import lil_matrix
from scipy.spatial.transform import Rotation

KEYS = 100
STARTS = (0.9, 1.0, 1.1)
EVALUATIONS = 600


def true_poses(d):
    """World-to-camera (R, t) of every frame in the scene's OpenGL axes, and the intrinsics."""
    frames, meta = [], None
    for split in ("train", "val"):
        with open(os.path.join(d, f"transforms_{split}.json")) as f:
            meta = json.load(f)
        frames += meta["frames"]
    poses = {}
    for x in frames:
        m = np.array(x["transform_matrix"])
        r = m[:3, :3].T
        poses[x["img_id"]] = (r, -r @ m[:3, 3])
    return poses, meta["focal_len"], meta["cx"], meta["cy"]


def helper_tracks(prepared, reach):
    frames = os.path.join(prepared, "ori_imgs")
    count = sum(1 for n in os.listdir(frames) if n.endswith(".jpg"))
    helper = os.path.join(os.path.dirname(__file__), "..", "prepare", "face", "nldf_face.py")
    with tempfile.TemporaryDirectory() as out:
        subprocess.run([sys.executable, helper, "frames", "--count", str(count), "--frames",
                        frames, "--out", out, "--track-reach", str(reach)], check=True, stdout=subprocess.DEVNULL,
                       stderr=subprocess.DEVNULL)
        return np.fromfile(os.path.join(out, "tracks.f32"), dtype="<f4").reshape(-1, 4), count


def bundle(obs, key_r, key_t, n_points, cam):
    """Huber bundle over key poses (the first fixed) and points; returns the refined key
    rotations and the final cost."""
    f, cx, cy = cam
    k_of, p_of = obs[:, 0].astype(int), obs[:, 1].astype(int)
    n_keys = len(key_r)
    rv0 = Rotation.from_matrix(np.array(key_r)).as_rotvec()
    t0 = np.array(key_t)
    rs = np.array(key_r)
    points = np.zeros((n_points, 3))
    for j in range(n_points):
        sel = p_of == j
        o, r, t = obs[sel], rs[k_of[sel]], t0[k_of[sel]]
        a = (o[:, 2] - cx)[:, None]
        rows = [-a * r[:, 2] - f * r[:, 0]]
        rhs = [a[:, 0] * t[:, 2] + f * t[:, 0]]
        a = (o[:, 3] - cy)[:, None]
        rows.append(-a * r[:, 2] + f * r[:, 1])
        rhs.append(a[:, 0] * t[:, 2] - f * t[:, 1])
        points[j] = np.linalg.lstsq(np.vstack(rows), np.concatenate(rhs), rcond=None)[0]

    def unpack(p):
        q = p[:6 * (n_keys - 1)].reshape(n_keys - 1, 6)
        return (np.vstack([rv0[:1], q[:, :3]]), np.vstack([t0[:1], q[:, 3:]]),
                p[6 * (n_keys - 1):].reshape(n_points, 3))

    def residuals(p):
        rv, t, x = unpack(p)
        r = Rotation.from_rotvec(rv).as_matrix()
        pc = np.einsum("nij,nj->ni", r[k_of], x[p_of]) + t[k_of]
        z = -pc[:, 2]
        return np.concatenate([cx + f * pc[:, 0] / z - obs[:, 2],
                               cy - f * pc[:, 1] / z - obs[:, 3]])

    p0 = np.concatenate([np.hstack([rv0[1:], t0[1:]]).ravel(), points.ravel()])
    m = len(obs)
    sparsity = lil_matrix((2 * m, len(p0)), dtype=int)
    for row in range(m):
        k, j = k_of[row], p_of[row]
        for rr in (row, row + m):
            if k > 0:
                sparsity[rr, 6 * (k - 1):6 * k] = 1
            sparsity[rr, 6 * (n_keys - 1) + 3 * j:6 * (n_keys - 1) + 3 * j + 3] = 1
    res = least_squares(residuals, p0, jac_sparsity=sparsity, loss="huber", f_scale=1.0,
                        x_scale="jac", max_nfev=EVALUATIONS, method="trf")
    return Rotation.from_rotvec(unpack(res.x)[0]).as_matrix(), float(res.cost), int(res.nfev)


def slopes(true_r, got_r, step):
    """Least-squares slope, per axis, of the rotation between keys `step` apart (got against
    true)."""
    a, b = [], []
    for i in range(0, len(true_r) - step):
        a.append(Rotation.from_matrix(true_r[i].T @ true_r[i + step]).as_rotvec())
        b.append(Rotation.from_matrix(got_r[i].T @ got_r[i + step]).as_rotvec())
    a, b = np.array(a), np.array(b)
    return [float((a[:, k] * b[:, k]).sum() / (a[:, k] ** 2).sum()) for k in range(3)]


def prepared_slopes(truth, prepared):
    """scripts/turn_slopes.py's slopes of PREPARED's track against TRUTH's: the rotation
    between frames 50 apart (every 5th frame), least squares per axis."""
    want, got = true_poses(truth)[0], true_poses(prepared)[0]
    ids = sorted(set(want) & set(got))
    a, b = [], []
    for i in ids[::5]:
        if i + 50 in want and i + 50 in got:
            a.append(Rotation.from_matrix(want[i][0] @ want[i + 50][0].T).as_rotvec())
            b.append(Rotation.from_matrix(got[i][0] @ got[i + 50][0].T).as_rotvec())
    a, b = np.array(a), np.array(b)
    return [float((a[:, k] * b[:, k]).sum() / (a[:, k] ** 2).sum()) for k in range(3)]


def video(truth, prepared, reach):
    """The three ends of one video's bundle."""
    poses, f, cx, cy = true_poses(truth)
    tracks, count = helper_tracks(prepared, reach)
    keys = np.round(np.linspace(0, count - 1, KEYS)).astype(int)
    slot = {int(k): i for i, k in enumerate(keys)}
    obs, n_points = [], 0
    for track in np.unique(tracks[:, 1]):
        seen = tracks[(tracks[:, 1] == track) & np.isin(tracks[:, 0].astype(int), keys)]
        if len(seen) < 3:
            continue
        obs += [(slot[int(i)], n_points, u, v) for i, _, u, v in seen]
        n_points += 1
    obs = np.array(obs)
    true_r = [poses[int(k)][0] for k in keys]
    step = max(1, round(50 * (KEYS - 1) / (count - 1)))
    ends = []
    for gain in STARTS:
        base = true_r[0]
        start = [Rotation.from_rotvec(gain * Rotation.from_matrix(r @ base.T).as_rotvec())
                 .as_matrix() @ base for r in true_r]
        got, cost, nfev = bundle(obs, start, [poses[int(k)][1] for k in keys], n_points,
                                 (f, cx, cy))
        pitch, yaw, roll = slopes(true_r, got, step)
        ends.append({"start_turn": gain, "cost": cost, "evaluations": nfev,
                     "slope_pitch": pitch, "slope_yaw": yaw, "slope_roll": roll})
        print(f"{truth}: start x{gain}: cost {cost:.1f}, turn slopes pitch {pitch:.3f} "
              f"yaw {yaw:.3f} roll {roll:.3f}", flush=True)
    with open(os.path.join(truth, "scene.json")) as fh:
        scene = json.load(fh)["config"]
    pitch, yaw, roll = prepared_slopes(truth, prepared)
    print(f"{truth}: prepared track's slopes pitch {pitch:.3f} yaw {yaw:.3f} roll {roll:.3f}")
    return {"head": scene["head"], "seed": scene["seed"], "size": scene["size"],
            "focal_len": f, "camera_distance": scene["camera_distance"], "frames": count,
            "key_frames": KEYS, "tracks": n_points, "observations": len(obs), "huber_px": 1.0,
            "ends": ends, "prepared_slope_pitch": pitch, "prepared_slope_yaw": yaw,
            "prepared_slope_roll": roll}


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--track-reach", type=float, default=0.0,
                   help="the tracks' reach above the face (nldf prepare --track-reach)")
    p.add_argument("out")
    p.add_argument("pairs", nargs="+", metavar="TRUTH PREPARED")
    args = p.parse_args()
    if len(args.pairs) % 2:
        p.error("give a PREPARED dataset after each TRUTH scene")
    pairs = args.pairs
    videos = [video(pairs[i], pairs[i + 1], args.track_reach) for i in range(0, len(pairs), 2)]
    with open(args.out, "w") as fh:
        json.dump({"evaluations": EVALUATIONS, "track_reach": args.track_reach,
                   "videos": videos}, fh, indent=1)


if __name__ == "__main__":
    main()
