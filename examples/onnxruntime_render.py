#!/usr/bin/env python3
"""Render one frame of an exported nldf model with numpy and onnxruntime alone.

Everything besides the graph comes from the model's own metadata (the keys of
model/src/contract/keys.rs): image size, intrinsics, near/far, the head's bounds, the default
camera pose, the audio input's shape and the background image. Rays go through every pixel as
AD-NeRF's get_rays makes them; rays that miss the head's bounds within [near, far] take the
background, the others the network's colour.

    python examples/onnxruntime_render.py MODEL.onnx [--audio aud.npy --frame F]
        [--out frame.npy] [--png frame.png]

Without --audio the audio features are zeros. --out writes the frame as float32 [H, W, 3]
exactly as computed (not clamped); --png writes it as an 8-bit PNG.
"""

import argparse
import base64
import json
import struct
import sys
import zlib

import numpy as np
import onnxruntime as ort

# Rays per onnxruntime call.
CHUNK = 65536


def read_png(data: bytes) -> np.ndarray:
    """Decodes an 8-bit, non-interlaced grey, RGB or RGBA PNG to uint8 [H, W, 3]."""
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError("background is not a PNG")
    pos, idat, header = 8, [], None
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        kind, body = data[pos + 4 : pos + 8], data[pos + 8 : pos + 8 + length]
        pos += 12 + length
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat.append(body)
        elif kind == b"IEND":
            break
    width, height, depth, color, _, _, interlace = header
    channels = {0: 1, 2: 3, 4: 2, 6: 4}.get(color)
    if depth != 8 or channels is None or interlace != 0:
        raise ValueError(f"unsupported PNG (bit depth {depth}, colour type {color})")
    raw = zlib.decompress(b"".join(idat))
    stride = width * channels
    out = np.zeros((height, stride), dtype=np.uint8)
    prev = np.zeros(stride, dtype=np.int32)
    for y in range(height):
        filt = raw[y * (stride + 1)]
        line = np.frombuffer(raw, np.uint8, stride, y * (stride + 1) + 1).astype(np.int32)
        if filt == 0:
            cur = line
        elif filt == 2:
            cur = (line + prev) & 0xFF
        else:
            cur = np.zeros(stride, dtype=np.int32)
            for x in range(stride):
                a = cur[x - channels] if x >= channels else 0
                b = prev[x]
                c = prev[x - channels] if x >= channels else 0
                if filt == 1:
                    pred = a
                elif filt == 3:
                    pred = (a + b) // 2
                else:
                    p = a + b - c
                    pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                    pred = a if pa <= pb and pa <= pc else (b if pb <= pc else c)
                cur[x] = (line[x] + pred) & 0xFF
        out[y] = cur
        prev = cur
    img = out.reshape(height, width, channels)
    if channels < 3:
        img = np.repeat(img[..., :1], 3, axis=2)
    return np.ascontiguousarray(img[..., :3])


def write_png(path: str, rgb: np.ndarray) -> None:
    """Writes uint8 [H, W, 3] as a PNG."""
    height, width, _ = rgb.shape
    rows = b"".join(b"\x00" + rgb[y].tobytes() for y in range(height))

    def chunk(kind: bytes, body: bytes) -> bytes:
        crc = zlib.crc32(kind + body) & 0xFFFFFFFF
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", crc)

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header))
        f.write(chunk(b"IDAT", zlib.compress(rows)) + chunk(b"IEND", b""))


def image_rays(meta: dict) -> tuple[np.ndarray, np.ndarray]:
    """Origins and directions [H * W, 3] (row by row) through every pixel from the default
    pose, as AD-NeRF's get_rays: direction [(i - cx) / f, -(j - cy) / f, -1] rotated by the
    camera-to-world matrix, in float32 in the same order of operations as nldf-core."""
    width, height = meta["nldf.image_width"], meta["nldf.image_height"]
    f, cx, cy = (np.float32(meta[k]) for k in ("nldf.focal", "nldf.cx", "nldf.cy"))
    c2w = np.array(meta["nldf.default_pose"], dtype=np.float32)
    j, i = np.meshgrid(
        np.arange(height, dtype=np.float32), np.arange(width, dtype=np.float32), indexing="ij"
    )
    dx = ((i - cx) / f).reshape(-1)
    dy = (-((j - cy) / f)).reshape(-1)
    dz = np.full_like(dx, -1.0)
    rot = c2w[:3, :3]
    directions = np.stack(
        [rot[r, 0] * dx + rot[r, 1] * dy + rot[r, 2] * dz for r in range(3)], axis=1
    ).astype(np.float32)
    origins = np.broadcast_to(c2w[:3, 3], directions.shape).astype(np.float32)
    return origins, directions


def hits_bounds(origins, directions, lo, hi, near, far) -> np.ndarray:
    """Which rays o + t d, t in [near, far], pass through the box [lo, hi] (slab method)."""
    n = len(origins)
    t0 = np.full(n, near, dtype=np.float32)
    t1 = np.full(n, far, dtype=np.float32)
    miss = np.zeros(n, dtype=bool)
    for a in range(3):
        o, d = origins[:, a], directions[:, a]
        flat = np.abs(d) < 1e-12
        miss |= flat & ((o < lo[a]) | (o > hi[a]))
        with np.errstate(divide="ignore", invalid="ignore"):
            u = (np.float32(lo[a]) - o) / d
            v = (np.float32(hi[a]) - o) / d
        t0 = np.where(flat, t0, np.maximum(t0, np.minimum(u, v)))
        t1 = np.where(flat, t1, np.minimum(t1, np.maximum(u, v)))
    return ~miss & np.isfinite(t0) & np.isfinite(t1) & (t1 > t0)


def neighbourhood(meta: dict, audio_path: str | None, frame: int) -> np.ndarray:
    """The audio input [att_frames, window, F] of `frame`: windows f - att_frames/2 ...,
    clamped to the track; zeros without a track."""
    seq = meta["nldf.audio_att_frames"]
    window, n_features = meta["nldf.audio_window"], meta["nldf.audio_features"]
    if audio_path is None:
        return np.zeros((seq, window, n_features), dtype=np.float32)
    track = np.load(audio_path).astype(np.float32)
    if track.ndim != 3 or track.shape[1:] != (window, n_features):
        raise ValueError(f"{audio_path}: shape {track.shape}, the model wants [N, {window}, {n_features}]")
    idx = np.clip(np.arange(seq) + frame - seq // 2, 0, len(track) - 1)
    return np.ascontiguousarray(track[idx])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("model", help="an .onnx file written by `nldf export`")
    parser.add_argument("--audio", help="audio features aud.npy [N, window, F]")
    parser.add_argument("--frame", type=int, default=0, help="video frame of the audio track")
    parser.add_argument("--out", help="write the frame as float32 .npy [H, W, 3]")
    parser.add_argument("--png", help="write the frame as an 8-bit PNG")
    args = parser.parse_args()

    session = ort.InferenceSession(args.model, providers=["CPUExecutionProvider"])
    raw = session.get_modelmeta().custom_metadata_map
    if raw.get("nldf.format") != "nldf-student":
        print(f"{args.model}: not an nldf model (no nldf.format metadata)", file=sys.stderr)
        return 1
    if "nldf.upsample" in raw:
        print(
            f"{args.model}: an upsampled ray graph (nldf.upsample): its rays are the head box's on a"
            " coarse grid; render it with nldf render, or its frame graph with examples/frame_graph.py",
            file=sys.stderr,
        )
        return 1
    plain = {
        "nldf.format",
        "nldf.audio_front_end",
        "nldf.background_file",
        "nldf.background_png",
        "nldf.weights_checksum",
    }
    meta = {k: (v if k in plain else json.loads(v)) for k, v in raw.items()}

    width, height = meta["nldf.image_width"], meta["nldf.image_height"]
    background = read_png(base64.b64decode(meta["nldf.background_png"]))
    if background.shape[:2] != (height, width):
        raise ValueError(f"background is {background.shape[1]}x{background.shape[0]}, image {width}x{height}")
    origins, directions = image_rays(meta)
    near, far = np.float32(meta["nldf.near"]), np.float32(meta["nldf.far"])
    lo = np.array(meta["nldf.bounds_lo"], dtype=np.float32)
    hi = np.array(meta["nldf.bounds_hi"], dtype=np.float32)
    hit = hits_bounds(origins, directions, lo, hi, near, far)
    audio = neighbourhood(meta, args.audio, args.frame)

    frame = (background.reshape(-1, 3).astype(np.float32) / np.float32(255.0)).astype(np.float32)
    # The model composites over the background itself (nldf.opacity is true): it takes each
    # ray's background colour as the input "background".
    index = np.flatnonzero(hit)
    for start in range(0, len(index), CHUNK):
        rows = index[start : start + CHUNK]
        feeds = {
            "rays_o": origins[rows],
            "rays_d": directions[rows],
            "audio": audio,
            "background": frame[rows].copy(),
        }
        (rgb,) = session.run(["rgb"], feeds)
        frame[rows] = rgb
    frame = frame.reshape(height, width, 3)

    print(f"{width}x{height} frame, {len(index)} rays through the head, the rest background")
    if args.out:
        np.save(args.out, frame)
        print(f"wrote {args.out}")
    if args.png:
        write_png(args.png, np.round(np.clip(frame, 0.0, 1.0) * 255.0).astype(np.uint8))
        print(f"wrote {args.png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
