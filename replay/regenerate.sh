#!/usr/bin/env bash
# Regenerates the shipped demo logs: 90 s of boom duty cycles each, normal and one per fault
# (abrupt at 45 s, severity 0.6).  Seeds 9001-9004 are never used for training.
#   bash replay/regenerate.sh
set -euo pipefail
cd "$(dirname "$0")"
monitor simulate --duration 90 --seed 9001 --out normal.log
monitor simulate --duration 90 --seed 9002 --fault piston_wear:0.6@45 --out piston_wear.log
monitor simulate --duration 90 --seed 9003 --fault spool_stroke:0.6@45 --out spool_stroke.log
monitor simulate --duration 90 --seed 9004 --fault spool_wear:0.6@45 --out spool_wear.log
