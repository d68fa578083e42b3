#!/usr/bin/env bash
# nldf prepare on the test videos with known truth: both synthetic heads at 128 and 512,
# turning up to 20 degrees (the default scene turns up to 12), 12 s each. Each scene and its
# MP4 are made once into WORK; every prepared dataset is scored against its scene by
# `nldf bench prepare`, whose JSON and table go to OUT (default results/prepare/videos). Then each
# 512 video again as a 128 dataset, scored against the 128 scene.
# SEED picks the scenes: 0 (the default) for the tuning videos every prepare setting was
# chosen on, 3 for the test videos the tables report (never used to choose anything).
# PREPARE_FLAGS are added to every `nldf prepare` (a setting under test, say
# `--track-reach 0.5`); NLDF names the binary to run (default: a release build of this tree).
# Usage: [SEED=3] [PREPARE_FLAGS=...] [NLDF=...] scripts/prepare_check.sh WORK [OUT]
set -euo pipefail
cd "$(dirname "$0")/.."
work=${1:?usage: scripts/prepare_check.sh WORK [OUT]}
out=${2:-results/prepare/videos}
seed=${SEED:-0}
mkdir -p "$work" "$out"
nldf=${NLDF:-target/release/nldf}
[ -n "${NLDF:-}" ] || cargo build --release --quiet --bin nldf
for size in 128 512; do
  for head in standard second; do
    name=${head}_${size}
    scene=$work/$name
    if [ ! -f "$scene.mp4" ]; then
      "$nldf" synth --out "$scene" --size "$size" --head "$head" --seed "$seed" --max-yaw-deg 20 \
        --video "$scene.mp4" --force >/dev/null
    fi
    rm -rf "$work/prepared_$name"
    # shellcheck disable=SC2086 # PREPARE_FLAGS is a list of flags.
    "$nldf" prepare --video "$scene.mp4" --out "$work/prepared_$name" --size "$size" \
      ${PREPARE_FLAGS:-} | tee "$out/$name.log"
    cp "$work/prepared_$name/prepare.json" "$out/${name}_prepare.json"
    "$nldf" bench prepare --truth "$scene" --prepared "$work/prepared_$name" \
      --out "$out/$name.json" | tee -a "$out/$name.log" || true
    python3 scripts/turn_slopes.py "$scene" "$work/prepared_$name" | tee -a "$out/$name.log"
  done
done
# The 512 videos prepared as 128 datasets (analysed at 512, then shrunk), scored against the
# 128 scenes: the same heads, poses and seeds at the smaller size.
for head in standard second; do
  name=${head}_512_as_128
  rm -rf "$work/prepared_$name"
  # shellcheck disable=SC2086 # PREPARE_FLAGS is a list of flags.
  "$nldf" prepare --video "$work/${head}_512.mp4" --out "$work/prepared_$name" --size 128 \
    ${PREPARE_FLAGS:-} | tee "$out/$name.log"
  cp "$work/prepared_$name/prepare.json" "$out/${name}_prepare.json"
  "$nldf" bench prepare --truth "$work/${head}_128" --prepared "$work/prepared_$name" \
    --out "$out/$name.json" | tee -a "$out/$name.log" || true
  python3 scripts/turn_slopes.py "$work/${head}_128" "$work/prepared_$name" \
    | tee -a "$out/$name.log"
done
# The logs and JSON name the work folder; results/ keeps no machine paths.
sed -i "s#$work/##g" "$out"/*.log "$out"/*.json
