#!/usr/bin/env bash
# `nldf prepare` on a real face: scikit-image's astronaut photo (NASA, public domain), which
# the scikit-image wheel carries, seen by a camera rolling about its optical axis (+-ROLL
# degrees, default 12, two cycles in 12 s, 256 x 256; scripts/photo_roll.py), with 12 s of
# nldf's synthetic speech as its sound. The roll is the whole true motion, so the prepared
# cameras are scored against it: rotations, the roll's slope, what turns about other axes,
# and how far the cameras, which should stand still, move. Writes OUT/{prepare.log,
# prepare.json,scores.json,photo_roll.png} (default results/prepare/photo_roll).
# Usage: [ROLL=12] [NLDF=...] scripts/prepare_photo_check.sh WORK [OUT]
set -euo pipefail
cd "$(dirname "$0")/.."
work=${1:?usage: scripts/prepare_photo_check.sh WORK [OUT]}
out=${2:-results/prepare/photo_roll}
nldf=${NLDF:-target/release/nldf}
[ -n "${NLDF:-}" ] || cargo build --release --quiet --bin nldf
"$nldf" prepare --setup > /dev/null
py=${NLDF_FACE_ENV:-$HOME/.cache/nldf/face-env}/venv/bin/python3
mkdir -p "$work" "$out"
if [ ! -f "$work/astronaut.png" ]; then
  "$py" -m pip download --quiet --no-deps --dest "$work/wheel" scikit-image==0.26.0
  "$py" -c "import glob, sys, zipfile; w = zipfile.ZipFile(glob.glob(sys.argv[1] + '/*.whl')[0]); open(sys.argv[2], 'wb').write(w.read('skimage/data/astronaut.png'))" \
    "$work/wheel" "$work/astronaut.png"
fi
"$py" scripts/photo_roll.py frames "$work/astronaut.png" "$work/frames" "${ROLL:-12}"
[ -f "$work/voice/aud.wav" ] || "$nldf" synth --out "$work/voice" --size 32 --seconds 12 \
  --supersample 1 --force > /dev/null
ffmpeg=$("$py" -c "import imageio_ffmpeg; print(imageio_ffmpeg.get_ffmpeg_exe())")
"$ffmpeg" -y -loglevel error -framerate 25 -i "$work/frames/%04d.png" -i "$work/voice/aud.wav" \
  -c:v libx264 -crf 18 -pix_fmt yuv420p -c:a aac -shortest "$work/roll.mp4"
"$nldf" prepare --video "$work/roll.mp4" --out "$work/prepared" --force > "$out/prepare.log"
cp "$work/prepared/prepare.json" "$out/prepare.json"
"$py" scripts/photo_roll.py score "$work/prepared" "$work/frames/roll.json" > "$out/scores.json"
"$py" scripts/photo_roll.py picture "$work/prepared" "$out/photo_roll.png"
cat "$out/scores.json"
# The logs and JSON name the work folder; results/ keeps no machine paths.
find "$out" -type f \( -name '*.log' -o -name '*.json' \) -exec sed -i "s#$work/##g" {} +
