"""The machine's practical f32 matrix peak: onnxruntime's sgemm on a 4096^3 product with
one thread per core (the README quotes this figure as the practical fp32 peak), best of 5 runs.

Usage: "$(scripts/python_env.sh)" scripts/matmul_peak.py [--n 4096]
"""

import argparse
import os
import time

import numpy as np
import onnx
import onnxruntime as ort
from onnx import TensorProto, helper


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=4096, help="matrix size (n x n by n x n)")
    parser.add_argument("--runs", type=int, default=5, help="timed runs; the best is kept")
    args = parser.parse_args()
    n = args.n
    graph = helper.make_graph(
        [helper.make_node("MatMul", ["a", "b"], ["c"])],
        "sgemm",
        [
            helper.make_tensor_value_info("a", TensorProto.FLOAT, [n, n]),
            helper.make_tensor_value_info("b", TensorProto.FLOAT, [n, n]),
        ],
        [helper.make_tensor_value_info("c", TensorProto.FLOAT, [n, n])],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 9  # the newest that onnxruntime 1.31 reads
    options = ort.SessionOptions()
    threads = os.cpu_count() or 1
    options.intra_op_num_threads = threads
    session = ort.InferenceSession(
        model.SerializeToString(), options, providers=["CPUExecutionProvider"]
    )
    rng = np.random.default_rng(0)
    a = rng.random((n, n), dtype=np.float32)
    b = rng.random((n, n), dtype=np.float32)
    session.run(None, {"a": a, "b": b})
    best = float("inf")
    for _ in range(args.runs):
        start = time.perf_counter()
        session.run(None, {"a": a, "b": b})
        best = min(best, time.perf_counter() - start)
    print(
        f"onnxruntime {ort.__version__} sgemm {n}^3, {threads} threads: "
        f"{2 * n**3 / best / 1e9:.1f} GFLOP/s (best of {args.runs}: {best * 1e3:.0f} ms)"
    )


if __name__ == "__main__":
    main()
