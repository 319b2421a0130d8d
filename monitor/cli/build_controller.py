"""``monitor build-controller``: a wheel for controllers, with the daemon's kernels compiled.

The controller's install then needs neither numba, LLVM nor a compiler: the wheel carries the
kernels of the live tick and of ``monitor detect`` compiled ahead of time by numba's ``pycc``
from their one (numba) source, in ``monitor/jit/compiled/`` (``monitor.jit.aot`` finds them
there), and its requirements are the package's without numba.  Built from the
monitor's source tree, on the controllers' architecture (pycc compiles for the machine it runs
on; ``--cpu generic`` makes the code serve every CPU of that architecture).
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

from monitor.errors import MonitorError

_NUMBA_LINE = re.compile(r'^\s*"numba[<>=!~ ][^"]*",\s*(#.*)?$')

#: What the wheel is built from: pyproject.toml's inputs (the package and its data folders).
_SOURCES = ("pyproject.toml", "README.md", "monitor", "dbc", "config", "replay")

# A distribution with a compiled part: bdist_wheel then tags the wheel with this Python's ABI
# and platform (cp311-cp311-linux_x86_64), not py3-none-any.
_SETUP_PY = """from setuptools import setup
from setuptools.dist import Distribution


class _Binary(Distribution):
    def has_ext_modules(self):
        return True


setup(distclass=_Binary)
"""


def add_subparser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "build-controller",
        help="build a controller's wheel: the daemon's kernels compiled, no numba needed",
        description="Compile the kernels of the live tick and of `monitor detect` ahead of "
        "time (numba pycc, from their numba source; needs numba and a C++ compiler here) "
        "and build a wheel of the monitor that carries them: `pip install` of that wheel on "
        "a controller of the same architecture and Python version runs `monitor run`, "
        "`detect`, `replay` and `demo` without numba, LLVM or a compiler. Run it in the "
        "monitor's source tree (an editable install or a checkout).",
    )
    p.add_argument(
        "--out", type=Path, default=Path("dist"), help="folder for the wheel (default: dist)"
    )
    p.add_argument(
        "--cpu",
        default="generic",
        help="CPU the code is tuned for: 'generic' (default) serves every CPU of this "
        "architecture; 'host' only CPUs like this one; or an LLVM CPU name (cortex-a72)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from monitor.cli._extras import require

    root = _source_tree()
    if args.out.exists() and not args.out.is_dir():
        raise MonitorError(f"--out {args.out}: exists and is not a folder")
    require("numba")
    if shutil.which("g++") is None:  # numba's pycc compiles through distutils' C++ driver
        raise MonitorError("needs a C++ compiler (g++) to compile the kernels; none on PATH")
    with tempfile.TemporaryDirectory(prefix="monitor-controller-") as tmp:
        stage = Path(tmp) / "src"
        _stage(root, stage)
        n = _compile(stage / "monitor" / "jit" / "compiled", args.cpu)
        wheel = _wheel(stage, args.out)
    size_mb = wheel.stat().st_size / 1e6
    print(
        f"build-controller: {wheel} ({size_mb:.1f} MB): {n} kernels compiled ahead of time "
        f"for CPU {args.cpu!r}; on the controller: pip install {wheel.name}",
        file=sys.stderr,
    )
    return 0


def _source_tree() -> Path:
    import monitor

    root = Path(monitor.__file__).resolve().parents[1]
    missing = [name for name in _SOURCES if not (root / name).exists()]
    if missing:
        raise MonitorError(
            f"needs the monitor's source tree (a checkout, or `pip install -e .`): "
            f"{root} has no {', '.join(missing)}"
        )
    return root


def _stage(root: Path, stage: Path) -> None:
    """A copy of the source tree's inputs, without caches or compiled leftovers."""
    skip = shutil.ignore_patterns("__pycache__", "*.pyc", "*.so", "*.pyd", "compiled")
    stage.mkdir(parents=True)
    for name in _SOURCES:
        src = root / name
        if src.is_dir():
            shutil.copytree(src, stage / name, ignore=skip)
        else:
            shutil.copy2(src, stage / name)
    (stage / "setup.py").write_text(_SETUP_PY, encoding="utf-8")
    _drop_numba(stage / "pyproject.toml")


def _drop_numba(pyproject: Path) -> None:
    """The package's requirements without numba (the wheel carries its kernels compiled);
    ``_wheel`` checks the built wheel's metadata."""
    lines = pyproject.read_text(encoding="utf-8").splitlines(keepends=True)
    kept = [line for line in lines if not _NUMBA_LINE.match(line)]
    if len(kept) != len(lines) - 1:
        raise MonitorError(f"{pyproject}: not one numba line in [project] dependencies")
    pyproject.write_text("".join(kept), encoding="utf-8")


def _compile(out: Path, cpu: str) -> int:
    """The ahead-of-time kernels into ``out`` under the shipped name; how many."""
    from monitor.cli.warm_up import through_jit
    from monitor.jit import KERNELS, Kernel, aot

    t0 = time.perf_counter()
    through_jit(simulator=False)
    kernels = [k for k in KERNELS if isinstance(k, Kernel) and k.aot]
    print(f"build-controller: compiling {len(kernels)} kernels (pycc)", file=sys.stderr)
    path = aot.build(kernels, out=out, name=aot.shipped_name(), cpu=cpu)
    print(
        f"build-controller: {path.name}, {path.stat().st_size / 1e6:.1f} MB, "
        f"{time.perf_counter() - t0:.0f} s",
        file=sys.stderr,
    )
    return len(kernels)


def _requirements(wheel: Path) -> list[str]:
    """The wheel's Requires-Dist without those of an extra."""
    from email.parser import Parser

    with zipfile.ZipFile(wheel) as z:
        meta = next(n for n in z.namelist() if n.endswith(".dist-info/METADATA"))
        parsed = Parser().parsestr(z.read(meta).decode("utf-8"))
    return [r for r in parsed.get_all("Requires-Dist") or [] if "extra ==" not in r]


def _wheel(stage: Path, out: Path) -> Path:
    """``pip wheel`` of the staged tree into ``out`` (setuptools and wheel from the index,
    as any build of the package); the wheel's path."""
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="monitor-wheel-") as tmp:
        done = subprocess.run(
            [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", tmp, str(stage)],
            capture_output=True,
            text=True,
            check=False,
        )
        if done.returncode != 0:
            last = (done.stderr.strip().splitlines() or ["(no output)"])[-1]
            raise MonitorError(f"pip wheel failed (exit {done.returncode}): {last}")
        (built,) = Path(tmp).glob("*.whl")
        needs = _requirements(built)
        if any(r.lower().startswith(("numba", "llvmlite")) for r in needs):
            raise MonitorError(f"the wheel still requires numba: {needs}")
        target = out / built.name
        shutil.move(str(built), target)
    return target
