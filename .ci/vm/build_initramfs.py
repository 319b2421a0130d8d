"""Build the test VM's boot files from an unpacked Debian kernel package.

    python3 build_initramfs.py KERNEL_ROOT OUT_DIR

KERNEL_ROOT holds ``boot/vmlinuz-VER`` and ``lib/modules/VER`` (``dpkg-deb -x`` of
linux-image-VER).  Writes to OUT_DIR:

* ``vmlinux``: the kernel without its xz wrapper (qemu boots it through the PVH entry
  point; skipping the in-guest decompression saves seconds under TCG);
* ``initramfs.cpio``: static busybox, ``init.sh`` (beside this file) as ``/init``, and the
  modules the VM needs (virtio transport, 9p, overlay, CAN and vcan) with their
  dependencies in load order, resolved by ``modprobe --show-depends``.

Only the standard library plus depmod/modprobe (kmod), busybox-static and cpio are used.
"""

from __future__ import annotations

import lzma
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

MODULES = ("virtio_pci", "9pnet_virtio", "9p", "overlay", "can", "can-raw", "can-bcm",
           "can-gw", "vcan")  # fmt: skip
BUSYBOX = Path("/bin/busybox")
XZ_MAGIC = b"\xfd7zXZ\x00"


def kernel_version(root: Path) -> str:
    versions = sorted(p.name for p in (root / "lib" / "modules").iterdir())
    if len(versions) != 1:
        sys.exit(f"build_initramfs: expected one kernel under {root}/lib/modules, got {versions}")
    return versions[0]


def extract_vmlinux(vmlinuz: Path, out: Path) -> None:
    data = vmlinuz.read_bytes()
    start = data.find(XZ_MAGIC)
    if start < 0:
        sys.exit(f"build_initramfs: no xz payload in {vmlinuz}")
    # A decompressor object stops at the end of the xz stream; the bzImage trailer follows.
    out.write_bytes(lzma.LZMADecompressor(format=lzma.FORMAT_XZ).decompress(data[start:]))


def module_paths(root: Path, version: str) -> list[Path]:
    """Module files in load order, each once (``insmod`` lines of modprobe's plan)."""
    subprocess.run(["depmod", "-b", str(root), version], check=True)
    ordered: list[Path] = []
    for name in MODULES:
        plan = subprocess.run(
            ["modprobe", "-d", str(root), "-S", version, "--show-depends", name],
            check=True, capture_output=True, text=True,
        ).stdout  # fmt: skip
        for line in plan.splitlines():
            parts = line.split()
            if parts[:1] == ["insmod"] and Path(parts[1]) not in ordered:
                ordered.append(Path(parts[1]))
            # "builtin NAME" lines need nothing loaded
    return ordered


def build(root: Path, out_dir: Path) -> None:
    version = kernel_version(root)
    out_dir.mkdir(parents=True, exist_ok=True)
    extract_vmlinux(root / "boot" / f"vmlinuz-{version}", out_dir / "vmlinux")
    with tempfile.TemporaryDirectory() as tmp:
        stage = Path(tmp)
        (stage / "bin").mkdir()
        (stage / "lib" / "modules").mkdir(parents=True)
        shutil.copy2(BUSYBOX, stage / "bin" / "busybox")
        names = []
        for path in module_paths(root, version):
            shutil.copy2(path, stage / "lib" / "modules" / path.name)
            names.append(path.name)
        (stage / "modules.list").write_text("\n".join(names) + "\n")
        init = stage / "init"
        shutil.copy2(Path(__file__).with_name("init.sh"), init)
        init.chmod(0o755)
        files = sorted(str(p.relative_to(stage)) for p in stage.rglob("*"))
        with (out_dir / "initramfs.cpio.tmp").open("wb") as fh:
            subprocess.run(["cpio", "--quiet", "-o", "-H", "newc"], cwd=stage,
                           input="\n".join(files).encode(), stdout=fh, check=True)  # fmt: skip
    (out_dir / "initramfs.cpio.tmp").replace(out_dir / "initramfs.cpio")
    print(f"build_initramfs: kernel {version}, {len(names)} modules -> {out_dir}")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    build(Path(sys.argv[1]), Path(sys.argv[2]))
