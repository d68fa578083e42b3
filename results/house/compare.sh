#!/usr/bin/env bash
# Runs the same tiny demo and frontier with the binary $1 into $2.
set -euo pipefail
BIN=$1; OUT=$2
rm -rf "$OUT"; mkdir -p "$OUT"
$BIN demo --quick --teacher-iters 40 --student-iters 40 --out "$OUT/run" > "$OUT/demo.log" 2>&1
$BIN bench frontier --run "$OUT/run" --data "$OUT/run/data" --frames 2 --adnerf-frames 0 --one-thread-frames 1 --timed-frames 1 --calibration-frames 2 --out "$OUT/frontier" > "$OUT/frontier.log" 2>&1
