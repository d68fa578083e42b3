#!/usr/bin/env bash
# The tuning of the feature tracks' reach above the face (`nldf prepare --track-reach`) on
# the tuning videos (seed 0, both heads, 128 and 512, made by scripts/prepare_check.sh into
# WORK): for each reach, scripts/prepare_check.sh on the same videos (its prepared datasets
# in WORK/reach_R/, its logs and scores in WORK/reach_R_scores/), then OUT/sweep.json: per
# reach and video, the poses' errors (`nldf bench prepare`) and how far the prepared track
# turns against the truth (scripts/turn_slopes.py; 1 turns as far). Default OUT:
# results/prepare/track_reach. NLDF names the binary (default: a release build).
# Usage: [NLDF=...] scripts/prepare_reach_sweep.sh WORK [OUT]
set -euo pipefail
cd "$(dirname "$0")/.."
work=${1:?usage: scripts/prepare_reach_sweep.sh WORK [OUT]}
out=${2:-results/prepare/track_reach}
reaches=(0 0.25 0.5)
mkdir -p "$out"
for reach in "${reaches[@]}"; do
  dir=$work/reach_$reach
  mkdir -p "$dir"
  for name in standard_128 standard_512 second_128 second_512; do
    [ -f "$work/$name.mp4" ] || { echo "no $work/$name.mp4: run scripts/prepare_check.sh $work first" >&2; exit 2; }
    ln -sfn "$(realpath "$work/$name")" "$dir/$name"
    ln -sfn "$(realpath "$work/$name.mp4")" "$dir/$name.mp4"
  done
  PREPARE_FLAGS="--track-reach $reach" bash scripts/prepare_check.sh "$dir" "${dir}_scores" >/dev/null
done
python3 - "$work" "$out/sweep.json" "${reaches[@]}" <<'EOF'
import json, re, sys
work, out, reaches = sys.argv[1], sys.argv[2], sys.argv[3:]
rows = []
for reach in reaches:
    for name in ["standard_128", "second_128", "standard_512", "second_512"]:
        scores = f"{work}/reach_{reach}_scores/{name}"
        with open(f"{scores}.json") as f:
            poses = json.load(f)["scores"]["poses"]
        with open(f"{scores}.log") as f:
            slopes = [float(s) for s in re.findall(r"slope ([0-9.]+)", f.read())]
        with open(f"{scores}_prepare.json") as f:
            report = json.load(f)
        # The reach the run used, as its report records it.
        tracks, used = report["tracks"]["tracks_used"], report["pose"]["track_reach"]
        rows.append({"track_reach": used, "video": name,
                     "rotation_mean_deg": poses["rotation_mean_deg"],
                     "rotation_worst_deg": poses["rotation_worst_deg"],
                     "position_mean": poses["position_mean"],
                     "position_worst": poses["position_worst"],
                     "turn_slope_pitch": slopes[0], "turn_slope_yaw": slopes[1],
                     "turn_slope_roll": slopes[2], "tracks_used": tracks})
with open(out, "w") as f:
    json.dump({"videos_seed": 0, "rows": rows}, f, indent=1)
print(f"wrote {out}")
EOF
