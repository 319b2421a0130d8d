#!/usr/bin/env bash
# Rebuilds the shipped model config/boom_default.model.npz from simulated normal boom duty
# cycles: patterns from 2 h (24 x 300 s, seeds 1-24), thresholds from 2 h more held out
# (seeds 25-48): eps0 = 2 x max normal J (N = 3000) and b0 = 2 x max normal B (60 s).
# Default preset, p = 1, at most 6000 patterns (clusters).  About four minutes.
#   bash config/train_default_model.sh
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
for seed in $(seq 1 48); do
  monitor simulate --duration 300 --seed "$seed" --out "$work/normal_$seed.csv"
done
monitor train "$work"/normal_{1..24}.csv --held-out "$work"/normal_{25..48}.csv \
  --out "$here/boom_default.model.npz"
