#!/usr/bin/env bash
# Run the monitor on 64-bit ARM (aarch64) under qemu user-mode emulation: a Debian arm64
# root (debootstrap), the project installed there with pip (aarch64 wheels of numpy, numba,
# llvmlite, scipy from PyPI), then the tests that exercise the numba kernels, the codec and
# the live path, and `monitor detect` on the shipped logs compared with this host's result.
#
# Needs root (chroot, binfmt_misc), debootstrap and qemu-user-static:
#   apt-get install -y debootstrap qemu-user-static
#   sudo bash deploy/arm64/check.sh [ROOT_DIR]      # default ~/.cache/hydraulic-monitor-arm64
# Emulation is ~10-30x slower than native; timings from here say nothing about a controller.
# Set ARM64_TESTS to choose the pytest selection (default below).
set -euo pipefail
repo=$(cd "$(dirname "$0")/../.." && pwd)
root=${1:-${XDG_CACHE_HOME:-$HOME/.cache}/hydraulic-monitor-arm64}
tests=${ARM64_TESTS:-"tests/test_grnn.py tests/test_grnn_index.py tests/test_dgrnn.py tests/test_detector.py tests/test_codec.py tests/test_sampler.py tests/test_live_e2e.py tests/test_startup.py"}

die() { echo "arm64 check: $*" >&2; exit 2; }
[ "$(id -u)" = 0 ] || die "needs root (chroot and binfmt_misc)"
command -v debootstrap >/dev/null || die "debootstrap missing: apt-get install -y debootstrap"
conf=/usr/lib/binfmt.d/qemu-aarch64.conf
[ -f "$conf" ] || die "qemu-user-static missing: apt-get install -y qemu-user-static"

# Register the aarch64 interpreter (flag F: usable inside the chroot) unless already there.
binfmt=/proc/sys/fs/binfmt_misc
[ -e "$binfmt/register" ] || mount -t binfmt_misc binfmt_misc "$binfmt"
[ -e "$binfmt/qemu-aarch64" ] || cat "$conf" > "$binfmt/register"

if [ ! -x "$root/usr/bin/python3" ]; then
    echo "arm64 check: debootstrap bookworm arm64 into $root"
    debootstrap --arch=arm64 --variant=minbase \
        --include=python3,python3-venv,python3-pip,python3-dev,g++,ca-certificates \
        bookworm "$root" http://deb.debian.org/debian
fi
# This host's CA bundle: pip inside the chroot must trust what the host trusts (proxies).
cp /etc/ssl/certs/ca-certificates.crt "$root/etc/ssl/certs/ca-certificates.crt"
rm -rf "$root/src" && mkdir -p "$root/src"
git -C "$repo" archive HEAD | tar -x -C "$root/src"
mountpoint -q "$root/proc" || mount --bind /proc "$root/proc"
trap 'umount "$root/proc" 2>/dev/null || true' EXIT

in_root() { chroot "$root" /usr/bin/env -i PATH=/venv/bin:/usr/bin:/bin HOME=/root \
    PIP_DISABLE_PIP_VERSION_CHECK=1 /bin/sh -c "cd /src && $1"; }
# g++ and the Python headers: `monitor warm-up` compiles the tick kernels ahead of time
# (tests/test_startup.py checks that the daemon's tick then runs without numba).
[ -x "$root/usr/bin/g++" ] || chroot "$root" /usr/bin/env -i PATH=/usr/bin:/bin \
    DEBIAN_FRONTEND=noninteractive /bin/sh -c "apt-get update -qq && apt-get install -y -qq g++ python3-dev >/dev/null"
in_root '[ -x /venv/bin/python ] || python3 -m venv /venv'
in_root 'pip install -q ".[test]"'
in_root 'python -c "import platform, numba, numpy; print(platform.machine(), \
    \"numba\", numba.__version__, \"numpy\", numpy.__version__)"'

# The same log through `monitor detect` here and in the chroot: same events, same J.
log=replay/piston_wear.log
PYTHONPATH="$repo" python3 -m monitor detect "$repo/$log" --summary "$root/tmp/host.json" >/dev/null
in_root "monitor detect $log --summary /tmp/arm64.json >/dev/null"
python3 - "$root/tmp/host.json" "$root/tmp/arm64.json" <<'PY'
import json, math, sys
host, arm = (json.load(open(p)) for p in sys.argv[1:])
for key in ("alarm", "first_alarm_t", "fault", "sensor_fault"):
    assert host[key] == arm[key], (key, host[key], arm[key])
assert math.isclose(host["max_J"], arm["max_J"], rel_tol=1e-9), (host["max_J"], arm["max_J"])
print(f"arm64 check: detect summary equals the host's ({arm['fault']} at "
      f"{arm['first_alarm_t']} s, max_J {arm['max_J']:.6g})")
PY
in_root "python -m pytest -q -p no:cacheprovider $tests"
