#!/usr/bin/env bash
# The demo's recipe with each teacher on the test scenes: `nldf demo --teacher mlp`
# and `nldf demo --teacher grid`, one after the other (never two at once), then the
# figures kept in results/grid/<machine>_<scene>_<teacher>/ and the summary rewritten.
#
#   scripts/grid_demos.sh WORK MACHINE [SCENE...]     SCENE: s0 | s1 | h2 (default: all)
#   TEACHERS=grid scripts/grid_demos.sh ...            the grid teacher's runs alone
set -euo pipefail
work=${1:?usage: scripts/grid_demos.sh WORK MACHINE [SCENE...]}
machine=${2:?usage: scripts/grid_demos.sh WORK MACHINE [SCENE...]}
shift 2
scenes=("$@")
[ ${#scenes[@]} -gt 0 ] || scenes=(s0 s1 h2)
nldf=${NLDF:-target/release/nldf}
mkdir -p "$work"
for scene in "${scenes[@]}"; do
  case $scene in
    s0) flags=(--seed 0) ;;
    s1) flags=(--seed 1) ;;
    h2) flags=(--head second) ;;
    *) echo "unknown scene $scene" >&2; exit 2 ;;
  esac
  for teacher in ${TEACHERS:-mlp grid}; do
    out="$work/${scene}_${teacher}"
    "$nldf" demo "${flags[@]}" --teacher "$teacher" --out "$out" > "$work/${scene}_${teacher}.log" 2>&1
    keep="results/grid/${machine}_${scene}_${teacher}"
    mkdir -p "$keep"
    for split in val novel voice; do
      cp "$out/eval/$split/metrics.json" "$keep/metrics_$split.json"
    done
    cp "$out/timing.json" "$keep/timing.json"
    cp "$out/teacher/config.json" "$keep/teacher_config.json"
  done
done
python3 scripts/grid_summary.py
