#!/usr/bin/env bash
# How much of the end-to-end check's gap the video's compression makes on its own: the
# teacher of the recipe trained on the scene with its true poses, masks and background, but
# with the training frames the video gives (the prepared dataset's JPEGs, which went
# through the MP4), then scored on every split against the scene's frames. Run after
# scripts/prepare_e2e.sh with the same WORK; HEAD picks the head (default second).
# The teacher takes the true-pose run's configuration (so its steps, grid and bounds);
# its metrics go to OUT (default results/prepare/e2e_test_grid/<head>/video_frames).
# Usage: [HEAD=second] [NLDF=...] scripts/e2e_video_frames.sh WORK [OUT]
set -euo pipefail
cd "$(dirname "$0")/.."
work=${1:?usage: scripts/e2e_video_frames.sh WORK [OUT]}
head=${HEAD:-second}
out=${2:-results/prepare/e2e_test_grid/$head/video_frames}
nldf=${NLDF:-target/release/nldf}
[ -n "${NLDF:-}" ] || cargo build --release --quiet --bin nldf
truth=$work/e2e_${head}_t128r512
prep=$work/e2e_${head}_prepared
config=$work/e2e_${head}_run_truth/teacher/config.json
for need in "$truth/scene.json" "$prep/transforms_train.json" "$config"; do
  [ -f "$need" ] || { echo "no $need: run scripts/prepare_e2e.sh $work first" >&2; exit 2; }
done
data=$work/e2e_${head}_video_frames
run=$work/e2e_${head}_run_video_frames
rm -rf "$data" "$run"
cp -r "$truth" "$data"
# Each training frame's image becomes the prepared one (the held-out frames stay the scene's).
for id in $(python3 -c "import json,sys; print(' '.join(str(f['img_id']) for f in json.load(open(sys.argv[1]))['frames']))" \
  "$data/transforms_train.json"); do
  rm "$data/head_imgs/$id.png"
  cp "$prep/head_imgs/$id.jpg" "$data/head_imgs/$id.jpg"
done
mkdir -p "$out"
"$nldf" train teacher --data "$data" --run "$run" --config "$config" > "$out/teacher.log" 2>&1
"$nldf" eval --run "$run" --data "$data" --split train --frames 30 --against "$truth" \
  --out "$run/eval/train" > "$out/eval.log"
for split in val novel voice; do
  "$nldf" eval --run "$run" --data "$data" --split "$split" --out "$run/eval/$split" >> "$out/eval.log"
done
for split in train val novel voice; do
  cp "$run/eval/$split/metrics.json" "$out/metrics_$split.json"
done
# The logs and JSON name the work folder; results/ keeps no machine paths.
find "$out" -type f \( -name '*.log' -o -name '*.json' \) -exec sed -i "s#$work/##g" {} +
