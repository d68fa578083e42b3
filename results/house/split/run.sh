#!/usr/bin/env bash
# The quick demo with each teacher, run by the binary from before the split (nldf_before)
# and the one after it (nldf_after), each in its own folder; then compare.py checks the
# weights, the exported graph and the scores. The caps are raised so that a busy machine
# still runs every step.
set -euo pipefail
for side in before after; do
  for t in mlp grid; do
    ./nldf_$side demo --quick --teacher $t --minutes 30 --student-minutes 30 --out ${side}_$t > ${side}_$t.log 2>&1
  done
done
python3 compare.py mlp grid > compare.json
