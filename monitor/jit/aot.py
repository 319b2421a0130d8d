"""Kernels compiled ahead of time, so the daemon and `monitor detect` never load numba.

numba and LLVM hold ~110 MB of a daemon's ~170 MB and take ~0.5 s to load, for a few
kernels: the live tick's (the DGRNN's one-sample prediction, the plausibility checks, the
bias window) and the offline detector's (the candump scan, the sample clock, the DGRNN over
a series on one thread, J and B over a series).  They are declared with ``jit(aot=True)``.
``monitor warm-up`` runs them once through the JIT, then compiles them with numba's ``pycc``
(their signatures taken from that run) into one CPython extension module in the cache
directory.  A ``Kernel`` declared ``aot`` calls the module's function when the module is
there and matches; otherwise it is a JIT kernel as before.  pycc compiles without the JIT's
fast-math flags: sums may differ from the JIT's in the last bits, never in NaN handling.

The module's name carries a digest of every source file that declares kernels, the numba
and Python versions and ``NUMBA_CPU_NAME``, so an upgraded monitor or numba never runs stale
code: it builds a new one at its next warm-up and uses the JIT until then.  ``MONITOR_AOT=0``
turns the module off (the side-by-side benchmark does).  Where: ``NUMBA_CACHE_DIR`` when set
(the systemd unit sets it), else ``__pycache__`` beside this file.

A controller's wheel (``monitor build-controller``) ships the module inside the package
(``compiled/`` beside this file), built for a CPU family (``generic``), so the controller
needs neither numba, LLVM nor a compiler.  Its name carries the digest of the kernels'
sources only (the Python ABI is in the file's suffix): numba is not there to ask its version,
and the module needs none of it at run time.  The warm-up's own module comes first.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import importlib.util
import json
import logging
import os
import sys
import weakref
from functools import cache
from pathlib import Path
from typing import Any, cast

import numpy as np

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
    """``monitor_aot_<digest>``: of the kernels' sources, numba, Python and the CPU name."""
    h = hashlib.sha256()
    try:
        h.update(importlib.metadata.version("numba").encode())
    except importlib.metadata.PackageNotFoundError:
        h.update(b"no numba")
    h.update(sys.version.encode())
    h.update(os.environ.get("NUMBA_CPU_NAME", "host").encode())
    _hash_sources(h)
    return f"monitor_aot_{h.hexdigest()[:16]}"


@cache
def shipped_name() -> str:
    """``monitor_aot_<digest>`` of the kernels' sources alone: the module a controller's
    wheel ships (``shipped_directory``)."""
    h = hashlib.sha256(b"shipped")
    _hash_sources(h)
    return f"monitor_aot_{h.hexdigest()[:16]}"


def shipped_directory() -> Path:
    """Where a controller's wheel carries its module: ``compiled/`` in this package."""
    return Path(__file__).resolve().parent / "compiled"


def _hash_sources(h: Any) -> None:
    for path in sorted(_PACKAGE.rglob("*.py")):
        text = path.read_bytes()
        if b"monitor.jit import" in text:  # a module that declares kernels
            h.update(path.relative_to(_PACKAGE).as_posix().encode())
            h.update(text)


def export_name(fn: Any) -> str:
    return f"{fn.__module__.replace('.', '_')}__{fn.__name__}"


@cache
def _module() -> tuple[Any, dict[str, Any]]:
    """The compiled module and its kernels' argument types, or (None, {}) (absent, turned
    off, or it does not load): the warm-up's, else the one a controller's wheel ships."""
    if not enabled():
        return None, {}
    for where, name in ((directory(), module_name()), (shipped_directory(), shipped_name())):
        mod = _load(where, name)
        if mod is not None:
            return mod, _read_specs(where / f"{name}.json")
    return None, {}


def _load(where: Path, name: str) -> Any:
    for path in sorted(where.glob(f"{name}.*")):
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


def loaded_from() -> str | None:
    """The file of the compiled module in use, or None (loads it)."""
    mod = _module()[0]
    return None if mod is None else str(mod.__file__)


def _suffixes() -> list[str]:
    from importlib.machinery import EXTENSION_SUFFIXES

    return EXTENSION_SUFFIXES


def compiled_function(fn: Any) -> Any:
    """The ahead-of-time compiled form of kernel function ``fn``, guarded by the argument
    types it was compiled for (``Guarded``), or None."""
    mod, specs = _module()
    name = export_name(fn)
    compiled = None if mod is None else getattr(mod, name, None)
    spec = specs.get(name)
    return None if compiled is None or spec is None else Guarded(compiled, spec)


class Guarded:
    """A pycc function with its argument types: pycc's wrappers do not check them (a
    float32 array where float64 was compiled crashes the process), so every call checks
    dtype, rank, layout and writability of arrays and the kind of scalars first.
    ``__call__`` raises TypeError on a mismatch (the kernel then hands over to the JIT)."""

    def __init__(self, fn: Any, spec: list[Any]) -> None:
        self.fn = fn
        self.spec = spec
        # The last call's arguments (arrays by weak reference: a whole recording is never
        # kept alive by this): the tick passes the same buffers every time, and an object
        # seen before needs no new check.
        self._seen: list[Any] = [None] * len(spec)

    def __call__(self, *args: Any) -> Any:
        seen = self._seen
        if len(args) != len(seen):
            raise TypeError("arguments of other types than those compiled ahead of time")
        for i, a in enumerate(args):
            old = seen[i]
            if type(old) is weakref.ReferenceType:
                old = old()
            if a is not old:
                if not _fits(a, self.spec[i]):
                    raise TypeError("arguments of other types than those compiled ahead of time")
                seen[i] = weakref.ref(a) if type(a) is np.ndarray else a
        return self.fn(*args)


def _fits(value: Any, spec: Any) -> bool:
    kind = spec[0]
    if kind == "array":
        _, dtype, ndim, layout, mutable = spec
        if not isinstance(value, np.ndarray) or value.ndim != ndim or value.dtype.str != dtype:
            return False
        flags = value.flags
        if (mutable and not flags.writeable) or not flags.aligned:
            return False
        return layout == "A" or (flags.c_contiguous if layout == "C" else flags.f_contiguous)
    if kind == "tuple":
        return (
            isinstance(value, tuple)
            and len(value) == len(spec[1])
            and all(map(_fits, value, spec[1]))
        )
    if kind == "int":
        return isinstance(value, (int, np.integer))
    if kind == "float":
        return isinstance(value, (int, float, np.integer, np.floating))
    if kind == "bool":
        return isinstance(value, (bool, np.bool_))
    return False


def _describe(t: Any) -> Any:
    """A numba type as ``_fits`` checks it (JSON-able); RuntimeError for kinds it cannot."""
    from numba.core import types

    if isinstance(t, types.Array):
        return ["array", np.dtype(str(t.dtype)).str, t.ndim, t.layout, bool(t.mutable)]
    if isinstance(t, types.BaseTuple):
        # Every concrete tuple type (uni-, heterogeneous, named) has ``types``; numba's
        # annotations declare it on the subclasses only.
        return ["tuple", [_describe(x) for x in cast(Any, t).types]]
    if isinstance(t, types.Boolean):
        return ["bool"]
    if isinstance(t, types.Integer):
        return ["int"]
    if isinstance(t, types.Float):
        return ["float"]
    raise RuntimeError(f"argument type {t} cannot be checked before an ahead-of-time call")


def _read_specs(path: Path) -> dict[str, Any]:
    try:
        return dict(json.loads(path.read_text(encoding="utf-8")))
    except (OSError, ValueError, TypeError):
        return {}


def build(
    kernels: list[Any], out: Path | None = None, name: str | None = None, cpu: str | None = None
) -> Path:
    """Compile ``kernels`` (``Kernel``s already run through the JIT once, so numba knows
    their argument types) into the module; returns its path.  Default: the warm-up's module
    (``directory``, ``module_name``, ``NUMBA_CPU_NAME`` or this CPU).  Needs a C++ compiler
    (numba's pycc builds through distutils' C++ driver)."""
    from numba.pycc import CC

    out = out or directory()
    name = name or module_name()
    out.mkdir(parents=True, exist_ok=True)
    cc = CC(name)
    cc.output_dir = str(out)
    cc.verbose = False
    cc.target_cpu = cpu or os.environ.get("NUMBA_CPU_NAME", "host")
    specs = {}
    for k in kernels:
        sigs = k.dispatcher.nopython_signatures
        if len(sigs) != 1:
            raise RuntimeError(f"{k!r} has {len(sigs)} compiled signatures, 1 expected")
        specs[export_name(k.py_func)] = [_describe(t) for t in sigs[0].args]
        cc.export(export_name(k.py_func), sigs[0])(k.py_func)
    cc.compile()
    (out / f"{name}.json").write_text(json.dumps(specs), encoding="utf-8")
    _module.cache_clear()
    found = sorted(p for p in out.glob(f"{name}.*") if p.name.endswith(tuple(_suffixes())))
    if not found:
        raise RuntimeError(f"pycc wrote no module to {out}")
    return found[0]
