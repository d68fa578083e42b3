#!/usr/bin/env python3
"""Rays each frame graph sends through its student at its default pose (`n_rays`), e.g. to
count an upsampler's coarse rays and its mouth patch's.

Usage: .venv/bin/python scripts/frame_rays.py FRAME.onnx [FRAME.onnx ...]
"""
import json
import sys

import numpy as np
import onnxruntime as ort


def main(paths):
    for path in paths:
        session = ort.InferenceSession(path, providers=["CPUExecutionProvider"])
        meta = session.get_modelmeta().custom_metadata_map
        samples = json.loads(meta["nldf.frame_audio"])["samples"]
        pose = np.array(json.loads(meta["nldf.default_pose"]), dtype=np.float32)
        keep = next(i for i in session.get_inputs() if i.name == "keep")
        feeds = {
            "audio": np.zeros(samples, dtype=np.float32),
            "pose": pose,
            "keep": np.ones(keep.shape, dtype=bool),
        }
        n_rays = session.run(["n_rays"], feeds)[0]
        print(f"{path}: {int(n_rays[0])} rays at the default pose")


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(sys.argv[1:])
