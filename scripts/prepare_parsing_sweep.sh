#!/usr/bin/env bash
# The tuning of the parsing's hanging chin (`--hang-depth`, `--foreground-diff`) and ears
# (`--ear-points`) on the tuning videos: each head's 512 video (seed 0) prepared at `--size 128` with the scene's
# focal length, scored by `nldf bench prepare` against the scene rendered at 512 and shrunk
# to 128 (`nldf synth --size 128 --render-size 512`, made once into WORK as
# scripts/prepare_e2e.sh makes it). Writes OUT/sweep.json: per setting, each head's pooled
# and worst head-mask IoU (default OUT: results/prepare/parsing_tuning).
# The videos come from scripts/prepare_check.sh run with SEED=0 into the same WORK.
# Usage: scripts/prepare_parsing_sweep.sh WORK [OUT]
set -euo pipefail
cd "$(dirname "$0")/.."
work=${1:?usage: scripts/prepare_parsing_sweep.sh WORK [OUT]}
out=${2:-results/prepare/parsing_tuning}
nldf=target/release/nldf
cargo build --release --quiet --bin nldf
mkdir -p "$out"
rows=$(mktemp)
trap 'rm -f "$rows"' EXIT
for head in standard second; do
  video=$work/${head}_512.mp4
  [ -f "$video" ] || { echo "no $video: run scripts/prepare_check.sh $work first" >&2; exit 2; }
  truth=$work/e2e_${head}_t128r512
  [ -f "$truth/scene.json" ] || "$nldf" synth --out "$truth" --size 128 --render-size 512 \
    --head "$head" --seed 0 --max-yaw-deg 20 --force >/dev/null
  focal=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['focal_len'])" \
    "$truth/transforms_train.json")
  # DEPTH:DIFF:EARS; depth 0 is the parsing without the chin, 0 ears cut along the jaw.
  for setting in 0:24:0 0.25:24:0 0.4:24:0 0.6:24:0 0.4:12:0 0.4:40:0 \
    0.4:24:2 0.4:24:3 0.4:24:4 0.4:24:5; do
    IFS=: read -r depth diff ears <<< "$setting"
    prep=$work/parsing_${head}_${depth}_${diff}_${ears}
    "$nldf" prepare --video "$video" --out "$prep" --size 128 --focal "$focal" --force \
      --hang-depth "$depth" --foreground-diff "$diff" --ear-points "$ears" >/dev/null
    "$nldf" bench prepare --truth "$truth" --prepared "$prep" --out "$prep/bench.json" \
      >/dev/null || true
    python3 -c "import json,sys; s=json.load(open(sys.argv[1]))['scores']; \
print(json.dumps({'head': sys.argv[2], 'hang_depth': float(sys.argv[3]), \
'foreground_diff': int(sys.argv[4]), 'ear_points': int(sys.argv[5]), \
'head_iou': s['head_iou'], 'head_iou_worst': s['head_iou_worst']}))" \
      "$prep/bench.json" "$head" "$depth" "$diff" "$ears" >> "$rows"
    rm -rf "$prep"
  done
done
python3 -c "import json,sys; rows=[json.loads(l) for l in open(sys.argv[1])]; \
json.dump({'videos': 'tuning (seed 0), 512 prepared at --size 128', 'rows': rows}, \
open(sys.argv[2], 'w'), indent=2)" "$rows" "$out/sweep.json"
echo "wrote $out/sweep.json"
