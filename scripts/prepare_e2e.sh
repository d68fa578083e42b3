#!/usr/bin/env bash
# The end-to-end check of `nldf prepare`: the recipe (`nldf train --data`) on each head's
# scene with its true poses, and on the dataset prepared from the scene's 512 video at
# `--size 128` with the scene's focal length. The truth is the scene rendered at 512 and
# shrunk to 128 (`nldf synth --size 128 --render-size 512`), as the prepared frames are.
# The videos come from scripts/prepare_check.sh run with the same SEED into the same WORK.
# Each run's log, the prepared dataset's scores and every split's metrics go to
# OUT/<head>/{truth,prepared}/ (default results/prepare/e2e_test); the prepared run's `val`
# also scored against the scene's frames (metrics_val_against_truth.json).
# HEADS picks the heads (default: standard second), SIDES the runs (default: truth prepared;
# the truth's runs do not read anything `nldf prepare` writes, so after a change to it alone
# SIDES=prepared suffices).
# PREPARE_FLAGS are added to `nldf prepare` (a setting under test, say `--ear-points 0`),
# TRAIN_FLAGS to `nldf train` (say `--train-seed 1`, a second run of the recipe).
# TEACHER picks the recipe's teacher (default grid, the recipe's; mlp: the quicker recipe,
# the one the tables of docs/prepare.md were made with).
# NLDF names the binary to run (default: a release build of this tree).
# Usage: [SEED=3] [TEACHER=mlp] [NLDF=...] [HEADS=second] [SIDES=prepared] [PREPARE_FLAGS=...] [TRAIN_FLAGS=...] scripts/prepare_e2e.sh WORK [OUT]
set -euo pipefail
cd "$(dirname "$0")/.."
work=${1:?usage: scripts/prepare_e2e.sh WORK [OUT]}
out=${2:-results/prepare/e2e_test}
seed=${SEED:-3}
nldf=${NLDF:-target/release/nldf}
[ -n "${NLDF:-}" ] || cargo build --release --quiet --bin nldf
for head in ${HEADS:-standard second}; do
  video=$work/${head}_512.mp4
  [ -f "$video" ] || { echo "no $video: run SEED=$seed scripts/prepare_check.sh $work first" >&2; exit 2; }
  truth=$work/e2e_${head}_t128r512
  [ -f "$truth/scene.json" ] || "$nldf" synth --out "$truth" --size 128 --render-size 512 \
    --head "$head" --seed "$seed" --max-yaw-deg 20 --force >/dev/null
  focal=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['focal_len'])" \
    "$truth/transforms_train.json")
  prep=$work/e2e_${head}_prepared
  rm -rf "$prep"
  mkdir -p "$out/$head/truth" "$out/$head/prepared"
  # shellcheck disable=SC2086 # PREPARE_FLAGS is a list of flags.
  "$nldf" prepare --video "$video" --out "$prep" --size 128 --focal "$focal" \
    ${PREPARE_FLAGS:-} > "$out/$head/prepared/prepare.log"
  "$nldf" bench prepare --truth "$truth" --prepared "$prep" --carry-held-out \
    --out "$out/$head/prepared/bench.json" >> "$out/$head/prepared/prepare.log" || true
  for side in ${SIDES:-truth prepared}; do
    data=$truth; [ "$side" = prepared ] && data=$prep
    run=$work/e2e_${head}_run_$side
    rm -rf "$run"
    # The caps only stop a slower machine; raised, so that a busy one still runs every step.
    # shellcheck disable=SC2086 # TRAIN_FLAGS is a list of flags.
    "$nldf" train --data "$data" --run "$run" --teacher "${TEACHER:-grid}" \
      --minutes 30 --student-minutes 150 ${TRAIN_FLAGS:-} \
      > "$out/$head/$side/train.log" 2>&1
    for split in val novel voice; do
      cp "$run/eval/$split/metrics.json" "$out/$head/$side/metrics_$split.json"
    done
    # The prepared `val` frames are the video's (compressed); scored again against the
    # scene's own frames and head masks, as the truth's run is (and as `novel` and `voice`
    # are, carried with the scene's images).
    if [ "$side" = prepared ]; then
      "$nldf" eval --run "$run" --data "$data" --split val --against "$truth" \
        --out "$run/eval/val_against_truth" > /dev/null
      cp "$run/eval/val_against_truth/metrics.json" "$out/$head/$side/metrics_val_against_truth.json"
    fi
  done
done
# The logs and JSON name the work folder; results/ keeps no machine paths.
find "$out" -type f \( -name '*.log' -o -name '*.json' \) -exec sed -i "s#$work/##g" {} +
