#!/usr/bin/env bash
set -u
# From the repository's root (three folders up); NLDF names the nldf binary to run.
cd "$(dirname "$0")/../../.."
N=${NLDF:-target/release/nldf}
R=runs/t512h2
step() { echo "== $1 $(date +%T)" >> runs/sharp/head2.progress; }
step synth
/usr/bin/time -v $N synth --size 512 --head second --seconds 12 --out $R/data > runs/sharp/head2_synth.log 2>&1 || { step FAILED; exit 1; }
step teacher
/usr/bin/time -v $N train teacher --data $R/data --run $R --config runs/t512/teacher/config.json > runs/sharp/head2_teacher.log 2>&1 || { step FAILED; exit 1; }
step student
/usr/bin/time -v $N train student --data $R/data --run $R --config results/sharp/xeon_512/student_config.json > runs/sharp/head2_student.log 2>&1 || { step FAILED; exit 1; }
step upsampler
/usr/bin/time -v $N train upsampler --data $R/data --run $R > runs/sharp/head2_up.log 2>&1 || { step FAILED; exit 1; }
for s in val novel voice; do
  step eval_$s
  $N eval --run $R --data $R/data --split $s --frames 20 --out runs/sharp/eval512h2/$s > runs/sharp/eval512h2_$s.log 2>&1 || { step FAILED; exit 1; }
done
step done
