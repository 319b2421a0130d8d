#!/usr/bin/env bash
# Rebuilds the shipped model config/boom_default.model.npz from simulated normal boom duty
# cycles (8 x 300 s, seeds 1-8; the last two are held out for J0), default preset, p = 1,
# at most 6000 patterns (clusters), N = 3000, eps0 = 2 x max normal J.  About a minute.
#   bash config/train_default_model.sh
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
for seed in 1 2 3 4 5 6 7 8; do
  monitor simulate --duration 300 --seed "$seed" --out "$work/normal_$seed.csv"
done
monitor train "$work"/normal_{1,2,3,4,5,6,7,8}.csv --out "$here/boom_default.model.npz"
