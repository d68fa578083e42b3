#!/usr/bin/env bash
# The posed ablation on the synthetic scene of one seed: the scene (with its novel, voice and
# sweep splits) and a small-preset teacher through `nldf demo`, then `nldf ablate
# --posed-minutes`: distilled students with and without pseudo views and a pixels-only one at
# equal total wall time, scored on val, novel and voice, with the pose-sweep strip.
# Usage: scripts/posed.sh [SEED] [TEACHER_MINUTES] [STUDENT_MINUTES] [OUT] [DEPTH]
# (defaults 0, 8, 15, runs/posed_seed$SEED, realtime: the README's table; the pilot used
# DEPTH 28 with 7 student minutes and 300 whole pseudo views)
# Set NLDF to a built binary to skip the release build.
set -euo pipefail
cd "$(dirname "$0")/.."
seed=${1:-0}
teacher_minutes=${2:-8}
student_minutes=${3:-15}
out=${4:-runs/posed_seed$seed}
depth=${5:-realtime}
if [ -z "${NLDF:-}" ]; then
  cargo build --release --bin nldf
  NLDF=target/release/nldf
fi
"$NLDF" demo --teacher mlp --seed "$seed" --minutes "$teacher_minutes" --student-minutes 0 --out "$out"
"$NLDF" ablate --data "$out/data" --run "$out" --depth "$depth" --posed-minutes "$student_minutes"
