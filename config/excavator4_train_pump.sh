#!/usr/bin/env bash
# Rebuilds the whole machine's shipped pump model config/pump_excavator4.pump.json (the
# shared load-sensing pump's margin law and its threshold, `monitor train --pump`) from the
# simulated normal operation the loops' models are trained on
# (config/excavator4_train_models.sh): the law fitted on 6 x 600 s of mixed duty cycles
# (seeds 101-106), the threshold (2 x the largest 20 s window's mean residual) on 12 x 600 s
# more held out (seeds 201-212).  About a minute after the simulations.
#   bash config/excavator4_train_pump.sh
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
for s in $(seq 101 106) $(seq 201 212); do echo "$s"; done | xargs -P "$(nproc)" -I{} \
  monitor simulate --machine excavator4 --duration 600 --seed {} --out "$work/n_{}.csv" >/dev/null
monitor train --pump "$work"/n_{101..106}.csv --held-out "$work"/n_{201..212}.csv \
  --config "$here/excavator4.yaml" --out "$here/pump_excavator4.pump.json"
