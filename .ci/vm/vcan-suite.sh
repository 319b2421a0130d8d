#!/usr/bin/env bash
# CI's SocketCAN part: the vcan tests (pytest -m vcan) inside the VM of run-in-vm.sh.
# On the host first: the small model of the tests (tests/vcan_model.sh) and numba's cache
# of the daemon's kernels, both with NUMBA_CPU_NAME=generic (the guest CPU differs from
# the host's; a generic cache is valid on both).  Logs go on the bus 6x slower than real
# time (MONITOR_VCAN_SLOWDOWN): Python in the guest is 25-40x slower, more on a busy host.
# Only the plugins the tests need are loaded (hypothesis' takes ~40 s to import there).
#   bash .ci/vm/vcan-suite.sh [extra pytest args]
set -euo pipefail
cd "$(dirname "$0")/../.."
t0=$(date +%s)
work="$(mktemp -d "${TMPDIR:-/tmp}/vcan-suite.XXXXXX")"
trap 'rm -rf "$work"' EXIT
# The real interpreter, not a pyenv shim: a shim costs ~15 s per start in the guest.
py="$(python3 -c 'import sys; print(sys.executable)')"
export PYTHONPATH="$PWD" NUMBA_CPU_NAME=generic
PYTHON="$py" bash tests/vcan_model.sh "$work/vcan.model.npz" >"$work/train.log" 2>&1 \
  || { cat "$work/train.log"; exit 1; }
"$py" - "$work/vcan.model.npz" <<'PY'
import sys
from pathlib import Path

from monitor.detection.offline import detect
from monitor.model.modelfile import load_model
from monitor.resources import resource_path
sys.path.insert(0, "tests")  # the tests' frame-by-frame reference reader
from naive_frames import recording_from_candump
from monitor.detection.ticker import Ticker

model = load_model(Path(sys.argv[1]))
Ticker(model)  # the daemon's per-tick kernel
detect(model, recording_from_candump(resource_path("replay", "normal.log")))  # the tests' reference
PY
echo "vcan-suite: host preparation $(($(date +%s) - t0)) s" >&2
MONITOR_VCAN_MODEL="$work/vcan.model.npz" MONITOR_VCAN_SLOWDOWN="${MONITOR_VCAN_SLOWDOWN:-6}" \
  MONITOR_VCAN_REQUIRED=1 \
  PYTEST_DISABLE_PLUGIN_AUTOLOAD=1 \
  bash .ci/vm/run-in-vm.sh "$py" -m pytest -q -s --color=no -p no:cacheprovider -o addopts=-ra \
  -m vcan --durations=0 tests/test_vcan_socketcan.py "$@"
echo "vcan-suite: total $(($(date +%s) - t0)) s" >&2
