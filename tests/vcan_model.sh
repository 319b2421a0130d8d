#!/usr/bin/env bash
# The small model of the vcan tests (Python in the CI VM is 25-40x slower than the host):
# horizon p = 1, at most 1000 GRNN patterns, a J window of 10 s, trained on two simulated
# normal runs (seeds 1 and 2, 200 s each).  About 30 s on a desktop.
#   bash tests/vcan_model.sh OUT.npz
set -euo pipefail
out="$1"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
py="${PYTHON:-python}"
for seed in 1 2; do
  "$py" -m monitor simulate --duration 200 --seed "$seed" --out "$work/normal_$seed.csv"
done
"$py" -m monitor train "$work"/normal_{1,2}.csv --horizon 1 --max-patterns 1000 --window 1000 \
  --out "$out"
