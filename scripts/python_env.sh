#!/usr/bin/env bash
# The project's Python environment for the ONNX tests and examples: `.venv` at the repository
# root with onnx, onnxruntime and numpy, and imageio-ffmpeg, whose static ffmpeg binary the
# MP4 test muxes with. The onnxruntime wheel also ships the library that the
# `ort` crate loads (ORT_DYLIB_PATH=.venv/lib/python3*/site-packages/onnxruntime/capi/
# libonnxruntime.so.1.31.1). Idempotent: once the pinned versions are there it asks no
# registry, so it runs offline.
# Usage: scripts/python_env.sh   (prints the interpreter's path on success)
set -euo pipefail
cd "$(dirname "$0")/.."

PYTHON=${PYTHON:-python3}
VENV=.venv
REQUIREMENTS=(onnx==1.23.2 onnxruntime==1.31.1 numpy imageio-ffmpeg==0.8.1)

want() {
  "$VENV/bin/python" - <<'PY' 2>/dev/null
import importlib.metadata as m
import sys
pins = {"onnx": "1.23.2", "onnxruntime": "1.31.1", "imageio-ffmpeg": "0.8.1"}
for name in ("onnx", "onnxruntime", "numpy", "imageio-ffmpeg"):
    version = m.version(name)
    if name in pins and version != pins[name]:
        sys.exit(1)
PY
}

if [ ! -x "$VENV/bin/python" ]; then
  "$PYTHON" -m venv "$VENV"
fi
if ! want; then
  "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check "${REQUIREMENTS[@]}"
  want || { echo "scripts/python_env.sh: $VENV lacks onnx, onnxruntime, numpy or imageio-ffmpeg" >&2; exit 1; }
fi
echo "$PWD/$VENV/bin/python"
