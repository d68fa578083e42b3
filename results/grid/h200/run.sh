#!/usr/bin/env bash
# Device batch: grid teacher at 512 (seed 0) against the MLP teacher, the second head's
# tuning scene (seed 7) with both teachers at 128, and student variants on the tuning scene.
# SMALL=1: a tiny smoke version.
set -u
T0=$(date +%s)
W=${W:-/tmp/w}; mkdir -p $W; cd $W
tar xJf $OLDPWD/.dev/pack.tar.xz
N=./nldf; OUTD=${OUT:-/tmp/out}; mkdir -p $OUTD
LIMIT=${LIMIT:-540}
S=${SMALL:-0}
nproc > info.txt; lscpu | head -20 >> info.txt; date >> info.txt
it() { if [ "$S" = 1 ]; then echo 20; else echo "$1"; fi; }
sz() { if [ "$S" = 1 ]; then echo 64; else echo 512; fi; }
# students on the tuning scene's grid teacher
for v in rt4500 rt10k w192 d24; do
  ( mkdir -p s7_$v && cp -r g7/teacher s7_$v/teacher
    export RAYON_NUM_THREADS=2
    s0=$(date +%s)
    if [ "$S" = 1 ]; then extra=(--iters 20); else extra=(); fi
    $N train student --data g7/data --run s7_$v --config cfg/$v.json "${extra[@]}" > s7_$v.log 2>&1
    for sp in val novel; do $N eval --run s7_$v --data g7/data --split $sp >> s7_$v.log 2>&1; done
    echo "wall $(( $(date +%s) - s0 ))" >> s7_$v.log ) &
done
# second head, tuning scene, both teachers at 128 (the demo's recipe, teacher only)
for t in mlp grid; do
  ( export RAYON_NUM_THREADS=2; s0=$(date +%s)
    $N demo --head second --seed 7 --teacher $t --student-iters 0 --out h7_$t $( [ "$S" = 1 ] && echo "--teacher-iters 20" ) > h7_$t.log 2>&1
    echo "wall $(( $(date +%s) - s0 ))" >> h7_$t.log ) &
done
# 512: one scene, then both teachers side by side (2 threads each), then their evaluations
( s0=$(date +%s)
  RAYON_NUM_THREADS=4 $N synth --out d512 --seed 0 --size $(sz) > d512.log 2>&1
  echo "synth wall $(( $(date +%s) - s0 ))" >> d512.log
  for t in mlp grid; do
    ( export RAYON_NUM_THREADS=2; s1=$(date +%s)
      $N train teacher --data d512 --run r512_$t --config cfg/teacher_$t.json $( [ "$S" = 1 ] && echo "--iters 20" ) > r512_$t.log 2>&1
      echo "teacher wall $(( $(date +%s) - s1 ))" >> r512_$t.log
      export RAYON_NUM_THREADS=4
      $N eval --run r512_$t --data d512 --split val >> r512_$t.log 2>&1
      $N eval --run r512_$t --data d512 --split novel --frames 28 >> r512_$t.log 2>&1
      echo "all wall $(( $(date +%s) - s1 ))" >> r512_$t.log ) &
  done
  wait ) &
while [ $(( $(date +%s) - T0 )) -lt $LIMIT ] && [ -n "$(jobs -r)" ]; do sleep 5; done
echo "elapsed $(( $(date +%s) - T0 ))" >> info.txt
tar czf $OUTD/res.tar.gz --exclude='*.safetensors' --exclude='*.png' --exclude='*.mp4' --exclude='d512' --exclude='g7' --exclude='data' --exclude='frames' info.txt *.log s7_* h7_* r512_* 2>/dev/null
ls -la $OUTD
