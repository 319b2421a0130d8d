#!/usr/bin/env bash
# Run a command in a throw-away Linux VM that has a real SocketCAN vcan0.
#
#   .ci/vm/run-in-vm.sh [--] COMMAND [ARG...]
#
# The VM boots Debian's kernel under qemu with software emulation (TCG; KVM guests hang on
# this kind of machine), sees this machine's whole file system read-only through virtio-9p
# with a tmpfs overlay on top (writes vanish with the VM), has vcan0 up, and runs COMMAND
# chrooted there in the current directory with the current environment.  Its output shows
# here; its exit status is this script's.  When the VM itself fails, the tail of the guest
# kernel log is printed.  Needs root for the apt installs on first use.
#
# Environment: MONITOR_VM_CACHE (kernel + initramfs, default ~/.cache/hydraulic-monitor-vm),
# VM_TIMEOUT_S (default 900), VM_CPUS (2), VM_MEM (2G).
set -euo pipefail
[[ "${1:-}" == "--" ]] && shift
if (($# == 0)); then
  sed -n '2,16p' "$0" >&2
  exit 2
fi
here="$(cd "$(dirname "$0")" && pwd)"
cache="${MONITOR_VM_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/hydraulic-monitor-vm}"
mkdir -p "$cache"

# -- host tools (apt) ----------------------------------------------------------------------
need=()
# busybox-static, not busybox: the initramfs has no libc.
for pkg in qemu-system-x86 can-utils busybox-static cpio kmod; do
  dpkg -s "$pkg" >/dev/null 2>&1 || need+=("$pkg")
done
if ((${#need[@]})); then
  echo "run-in-vm: installing ${need[*]}" >&2
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${need[@]}" >/dev/null
fi

# -- kernel and initramfs (cached) ------------------------------------------------------------
kpkg="$(apt-cache depends linux-image-amd64 2>/dev/null | awk '/Depends: linux-image-[0-9]/{print $2; exit}')"
if [[ -z "$kpkg" ]]; then
  apt-get update -qq
  kpkg="$(apt-cache depends linux-image-amd64 | awk '/Depends: linux-image-[0-9]/{print $2; exit}')"
fi
stamp="$(cat "$here/init.sh" "$here/build_initramfs.py" | sha256sum | cut -c1-16)"
boot="$cache/$kpkg-$stamp"
if [[ ! -f "$boot/initramfs.cpio" ]]; then
  rm -rf "$cache/deb" && mkdir -p "$cache/deb"
  echo "run-in-vm: fetching $kpkg" >&2
  (cd "$cache/deb" && apt-get download -q "$kpkg" 2>&1 | grep -v '^W: Download is performed unsandboxed' >&2 || true)
  dpkg-deb -x "$cache"/deb/"$kpkg"_*.deb "$cache/deb/root"
  python3 "$here/build_initramfs.py" "$cache/deb/root" "$boot" >&2
  rm -rf "$cache/deb"
fi

# -- the command, its directory and environment -------------------------------------------------
share="$(mktemp -d "${TMPDIR:-/tmp}/vm-share.XXXXXX")"
trap 'rm -rf "$share"' EXIT
{
  echo "# written by run-in-vm.sh"
  export -p | grep -Ev '^declare -x (PWD|OLDPWD|SHLVL|_|TERM|TMUX|TMUX_PANE|DISPLAY)='
  echo "export TERM=dumb"
  printf 'cd %q || exit 125\n' "$PWD"
  printf 'exec'
  printf ' %q' "$@"
  printf '\n'
} >"$share/cmd.sh"

# -- boot ------------------------------------------------------------------------------------
SECONDS=0
set +e
timeout --foreground "${VM_TIMEOUT_S:-900}" qemu-system-x86_64 \
  -machine pc -accel tcg,thread=multi -cpu max -smp "${VM_CPUS:-2}" -m "${VM_MEM:-2G}" \
  -nodefaults -no-reboot -display none -monitor none -serial stdio \
  -kernel "$boot/vmlinux" -initrd "$boot/initramfs.cpio" \
  -append "console=ttyS0 panic=-1 quiet loglevel=3" \
  -virtfs local,path=/,mount_tag=hostroot,security_model=none,readonly=on,multidevs=remap \
  -virtfs "local,path=$share,mount_tag=out,security_model=none" \
  </dev/null 2>&1 | sed -u 's/\r$//'
vm_status=${PIPESTATUS[0]}
set -e
elapsed=$SECONDS
if [[ -f "$share/rc" ]]; then
  rc="$(cat "$share/rc")"
  echo "run-in-vm: command exited $rc; VM ran ${elapsed} s" >&2
  if [[ "$rc" != 0 && -f "$share/dmesg.txt" ]]; then
    echo "run-in-vm: guest kernel log (tail):" >&2
    tail -n 30 "$share/dmesg.txt" >&2
  fi
  exit "$rc"
fi
echo "run-in-vm: the VM stopped without a result (qemu status $vm_status, 124 = timeout)" >&2
[[ -f "$share/dmesg.txt" ]] && tail -n 40 "$share/dmesg.txt" >&2
exit 1
