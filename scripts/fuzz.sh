#!/usr/bin/env bash
# Longer fuzzing of nldf's readers (WAV, aud.npy, safetensors, config JSON, ONNX metadata,
# transforms JSON) with libFuzzer through cargo-fuzz. The test suite runs the same harnesses
# (tests/fuzz.rs) for a bounded number of seeded cases; this runs each for longer, guided by
# coverage, starting from the suite's valid seed files. A crash is saved under
# fuzz/artifacts/<target>/ and fails the script.
#
# Usage: scripts/fuzz.sh [seconds per target, default 60] [target ...]
#
# cargo-fuzz comes from crates.io (installed here when missing). libFuzzer's coverage
# instrumentation takes flags that stable rustc accepts only with RUSTC_BOOTSTRAP=1, which
# this script sets for the fuzz build alone; no sanitizer runtime is needed
# (--sanitizer none): a panic is the crash signal.
set -euo pipefail
cd "$(dirname "$0")/.."

seconds=${1:-60}
shift || true
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(wav npy safetensors config onnx transforms)

if ! cargo fuzz --version >/dev/null 2>&1; then
  cargo install cargo-fuzz --locked
fi

# Seed corpora: the suite's valid files for every reader.
NLDF_FUZZ_SEED_DIR="$PWD/fuzz/corpus" NLDF_FUZZ_CASES=1 \
  cargo test -q -p nldf-tests --test suite fuzz_ >/dev/null

export RUSTC_BOOTSTRAP=1
status=0
for t in "${targets[@]}"; do
  echo "== $t (${seconds} s)"
  mkdir -p "fuzz/corpus/$t"
  log="fuzz/$t.log"
  if cargo fuzz run --sanitizer none "$t" "fuzz/corpus/$t" -- \
      -max_total_time="$seconds" -rss_limit_mb=4096 -max_len=65536 -print_final_stats=1 \
      >"$log" 2>&1; then
    grep -E "^(stat::number_of_executed_units|stat::average_exec_per_sec|Done)" "$log" || true
  else
    tail -n 30 "$log" >&2
    echo "$t: failed; crashes (if any) are in fuzz/artifacts/$t, the log in $log" >&2
    status=1
  fi
done
exit $status
