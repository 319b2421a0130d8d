"""The live tick's kernels compiled ahead of time, so the daemon never loads numba.

numba and LLVM hold ~110 MB of a daemon's ~170 MB and take ~0.5 s to load, for the two
kernels a tick calls (the DGRNN's one-sample prediction and the plausibility checks; both
declared with ``jit(aot=True)``).  ``monitor warm-up`` runs them once through the JIT, then
compiles them with numba's ``pycc`` (their signatures taken from that run) into one CPython
extension module in the cache directory.  A ``Kernel`` declared ``aot`` calls the module's
function when the module is there and matches; otherwise it is a JIT kernel as before.

The module's name carries a digest of every source file that declares kernels, the numba
and Python versions and ``NUMBA_CPU_NAME``, so an upgraded monitor or numba never runs stale
code: it builds a new one at its next warm-up and uses the JIT until then.  ``MONITOR_AOT=0``
turns the module off (the side-by-side benchmark does).  Where: ``NUMBA_CACHE_DIR`` when set
(the systemd unit sets it), else ``__pycache__`` beside this file.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import importlib.util
import logging
import os
import sys
from functools import cache
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

_PACKAGE = Path(__file__).resolve().parents[1]


def enabled() -> bool:
    return os.environ.get("MONITOR_AOT", "1") != "0"


def directory() -> Path:
    """Where the module is written and looked for."""
    env = os.environ.get("NUMBA_CACHE_DIR")
    return Path(env) if env else Path(__file__).resolve().parent / "__pycache__"


@cache
def module_name() -> str:
    """``monitor_tick_<digest>``: of the kernels' sources, numba, Python and the CPU name."""
    h = hashlib.sha256()
    try:
        h.update(importlib.metadata.version("numba").encode())
    except importlib.metadata.PackageNotFoundError:
        h.update(b"no numba")
    h.update(sys.version.encode())
    h.update(os.environ.get("NUMBA_CPU_NAME", "host").encode())
    for path in sorted(_PACKAGE.rglob("*.py")):
        text = path.read_bytes()
        if b"monitor.jit import" in text:  # a module that declares kernels
            h.update(path.relative_to(_PACKAGE).as_posix().encode())
            h.update(text)
    return f"monitor_tick_{h.hexdigest()[:16]}"


def export_name(fn: Any) -> str:
    return f"{fn.__module__.replace('.', '_')}__{fn.__name__}"


@cache
def _module() -> Any:
    """The compiled module, or None (absent, turned off, or it does not load)."""
    if not enabled():
        return None
    name = module_name()
    for path in sorted(directory().glob(f"{name}.*")):
        if not path.name.endswith(tuple(_suffixes())):
            continue
        try:
            spec = importlib.util.spec_from_file_location(name, path)
            if spec is None or spec.loader is None:
                continue
            mod = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(mod)
        except Exception as exc:  # a damaged file: the JIT kernels will do
            log.warning("ahead-of-time kernels in %s not loaded (%s); using the JIT", path, exc)
            return None
        return mod
    return None


def _suffixes() -> list[str]:
    from importlib.machinery import EXTENSION_SUFFIXES

    return EXTENSION_SUFFIXES


def compiled_function(fn: Any) -> Any:
    """The ahead-of-time compiled form of kernel function ``fn``, or None."""
    mod = _module()
    return None if mod is None else getattr(mod, export_name(fn), None)


def build(kernels: list[Any]) -> Path:
    """Compile ``kernels`` (``Kernel``s already run through the JIT once, so numba knows
    their argument types) into the module; returns its path.  Needs a C++ compiler (numba's
    pycc builds through distutils' C++ driver)."""
    from numba.pycc import CC

    out = directory()
    out.mkdir(parents=True, exist_ok=True)
    cc = CC(module_name())
    cc.output_dir = str(out)
    cc.verbose = False
    cc.target_cpu = os.environ.get("NUMBA_CPU_NAME", "host")
    for k in kernels:
        sigs = k.dispatcher.nopython_signatures
        if len(sigs) != 1:
            raise RuntimeError(f"{k!r} has {len(sigs)} compiled signatures, 1 expected")
        cc.export(export_name(k.py_func), sigs[0])(k.py_func)
    cc.compile()
    _module.cache_clear()
    found = sorted(out.glob(f"{module_name()}.*"))
    if not found:
        raise RuntimeError(f"pycc wrote no module to {out}")
    return found[0]
