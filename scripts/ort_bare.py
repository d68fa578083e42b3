"""The bare onnxruntime session from Python, to set beside `nldf bench render`'s "bare
onnxruntime" row: one exported model, random rays of the frame's count, in batches, with
2 intra-op threads and one inter-op thread, as nldf's session runs it.

Usage: .venv/bin/python scripts/ort_bare.py MODEL.onnx [RAYS] [BATCH] [SPIN]
(RAYS defaults to 8150, the default frame's head rays at 128 x 128; BATCH to 4096; SPIN,
1 or 0, to onnxruntime's default of 1). Prints the median of 21 frames after 3 untimed.
"""

import sys
import time

import numpy as np
import onnxruntime as ort


def main() -> None:
    model = sys.argv[1]
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 8150
    batch = int(sys.argv[3]) if len(sys.argv) > 3 else 4096
    spin = sys.argv[4] if len(sys.argv) > 4 else "1"
    so = ort.SessionOptions()
    so.intra_op_num_threads = 2
    so.inter_op_num_threads = 1
    so.add_session_config_entry("session.intra_op.allow_spinning", spin)
    if len(sys.argv) > 5:
        so.add_session_config_entry("session.force_spinning_stop", sys.argv[5])
    session = ort.InferenceSession(model, so, providers=["CPUExecutionProvider"])
    rng = np.random.default_rng(0)
    audio_shape = [i.shape for i in session.get_inputs() if i.name == "audio"][0]
    origins = (0.1 * rng.standard_normal((n, 3))).astype(np.float32)
    directions = rng.standard_normal((n, 3)).astype(np.float32)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    audio = np.full(audio_shape, -1.0, dtype=np.float32)
    # A model with opacity also takes each ray's background colour.
    has_background = any(i.name == "background" for i in session.get_inputs())
    background = np.full((n, 3), 0.5, dtype=np.float32)

    def frame() -> None:
        for start in range(0, n, batch):
            feeds = {
                "rays_o": origins[start : start + batch],
                "rays_d": directions[start : start + batch],
                "audio": audio,
            }
            if has_background:
                feeds["background"] = background[start : start + batch]
            session.run(None, feeds)

    for _ in range(3):
        frame()
    times = []
    for _ in range(21):
        t = time.perf_counter()
        frame()
        times.append(time.perf_counter() - t)
    print(
        f"{model}: {n} rays in batches of {batch}, 2 threads, spinning {spin}: "
        f"median {1e3 * np.median(times):.1f} ms"
    )


if __name__ == "__main__":
    main()
