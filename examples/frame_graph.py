#!/usr/bin/env python3
"""A talking head from a WAV with an nldf frame graph (`nldf export --frame`), numpy and
onnxruntime alone: python examples/frame_graph.py models/demo/frame.onnx speech.wav out/
writes out/frame_00000.png, ... (25 fps) at the model's default pose."""
import json, pathlib, struct, sys, wave, zlib
import numpy as np, onnxruntime as ort

model, wav, out = sys.argv[1], sys.argv[2], pathlib.Path(sys.argv[3])
session = ort.InferenceSession(model, providers=["CPUExecutionProvider"])
meta = session.get_modelmeta().custom_metadata_map
audio = json.loads(meta["nldf.frame_audio"])  # which samples one frame reads
pose = np.array(json.loads(meta["nldf.default_pose"]), np.float32)  # camera to world
keep = np.ones(next(i.shape for i in session.get_inputs() if i.name == "keep"), bool)  # render all
with wave.open(wav) as w:
    if w.getsampwidth() != 2:
        sys.exit(f"{wav}: 16-bit PCM WAV expected")
    pcm = np.frombuffer(w.readframes(w.getnframes()), "<i2").reshape(-1, w.getnchannels())
    x, rate = pcm.mean(axis=1) / 32768.0, w.getframerate()
n = round(len(x) * 16000 / rate)  # to 16 kHz, linearly (nldf resamples by windowed sinc)
x = np.interp(np.arange(n) * rate / 16000, np.arange(len(x)), x).astype(np.float32)
step, size, offset = audio["samples_per_frame"], audio["samples"], audio["offset"]
off_track = np.full(size, np.nan, np.float32)  # NaN marks samples before or after the track
track = np.concatenate([off_track, x, off_track])

def write_png(path, rgb):
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    h, w, _ = rgb.shape
    rows = b"".join(b"\0" + row.tobytes() for row in rgb)
    header = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    body = chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(rows)) + chunk(b"IEND", b"")
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + body)

out.mkdir(parents=True, exist_ok=True)
for f in range(n // step):
    chunk = track[size + f * step + offset :][:size]
    (image,) = session.run(["image"], {"audio": chunk, "pose": pose, "keep": keep})
    write_png(out / f"frame_{f:05d}.png", (np.clip(image, 0, 1) * 255).round().astype(np.uint8))
print(f"wrote {n // step} frames to {out}")
