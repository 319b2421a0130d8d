"""The one place for numba options, so every kernel is compiled the same way, and lazily.

``FASTMATH`` lists LLVM fast-math flags explicitly instead of ``fastmath=True``: ``nnan`` and
``ninf`` are left out on purpose, because with them LLVM may assume no NaN/inf exists and
fold away ``np.isnan`` checks and ``inf`` sentinels that the kernels rely on (missing samples
are NaN, excluded neighbours are +inf distances).  The remaining flags only allow reordering
and contraction, which changes results in the last bits, never NaN semantics.

Importing a module of kernels imports no numba: ``jit`` returns a :class:`Kernel` that
builds its numba dispatcher at its first call (numba and LLVM take ~60 MB and ~0.5 s to
load).  A daemon whose tick kernels were compiled ahead of time (``monitor.jit.aot``) never
loads numba at all.  At the first call every kernel gets its dispatcher at once, and the
modules of the monitor see numba's own objects under the kernels' names (and ``prange``),
because kernels call kernels through their module's globals and numba types those.
"""

from __future__ import annotations

import functools
import sys
import threading
from collections.abc import Callable
from typing import Any, TypeVar

FASTMATH: set[str] = {"nsz", "arcp", "contract", "afn", "reassoc"}

F = TypeVar("F", bound=Callable[..., Any])

__all__ = [
    "FASTMATH",
    "Kernel",
    "cache_stats",
    "jit",
    "pjit",
    "prange",
    "get_num_threads",
    "numba_loaded",
]

#: Every kernel declared through ``jit``/``pjit``, so start-up can say what the cache gave.
KERNELS: list[Any] = []

_lock = threading.Lock()
_numba: Any = None  # the numba module, once loaded


def prange(*args: int) -> range:
    """``range`` in plain Python; numba's ``prange`` inside a compiled kernel."""
    return range(*args)


class Kernel:
    """A function compiled by numba (``njit`` with ``options``) at its first call."""

    def __init__(self, fn: Callable[..., Any], options: dict[str, Any], aot: bool = False) -> None:
        functools.update_wrapper(self, fn)
        self.py_func = fn
        self.options = options
        self.aot = aot  # compiled ahead of time by ``monitor warm-up`` (monitor.jit.aot)
        self._dispatcher: Any = None
        self._call: Callable[..., Any] | None = None  # what a call runs, once resolved

    @property
    def dispatcher(self) -> Any:
        if self._dispatcher is None:
            _load_numba()
        return self._dispatcher

    @property
    def compiled(self) -> bool:
        """Whether numba has built this kernel's dispatcher (numba is loaded)."""
        return self._dispatcher is not None

    @property
    def ahead_of_time(self) -> bool:
        """Whether calls run the ahead-of-time compiled function (no numba needed)."""
        return self._call is not None and self._call is not self._dispatcher

    def __call__(self, *args: Any) -> Any:
        call = self._call
        if call is None:
            call = self._resolve()
        return call(*args)

    @property
    def runs_ahead_of_time(self) -> bool:
        """Whether a call would run ahead-of-time code (resolves the kernel, loads no numba)."""
        if self._call is None:
            self._resolve()
        return self.ahead_of_time

    def _resolve(self) -> Callable[..., Any]:
        if self.aot and self._dispatcher is None:
            from monitor.jit import aot

            fn = aot.compiled_function(self.py_func)
            if fn is not None:

                def call(*args: Any) -> Any:
                    try:
                        return fn(*args)
                    except TypeError:  # argument types warm-up never saw: the JIT takes them
                        return self.dispatcher(*args)

                self._call = call
                return call
        self._call = self.dispatcher
        return self._call

    def __getattr__(self, name: str) -> Any:  # signatures, stats, ...: the dispatcher's
        if name.startswith("__"):
            raise AttributeError(name)
        return getattr(self.dispatcher, name)

    def __repr__(self) -> str:
        return f"<Kernel {self.py_func.__module__}.{self.py_func.__qualname__}>"


def jit(fn: F | None = None, *, aot: bool = False, **options: Any) -> Any:
    """``njit`` with on-disk caching and the project's fast-math flags (serial kernels),
    compiled at the first call.  ``aot``: a kernel of the live tick, also compiled ahead of
    time by ``monitor warm-up`` (``monitor.jit.aot``)."""
    opts: dict[str, Any] = {"cache": True, "fastmath": FASTMATH, **options}
    if fn is None:
        return lambda f: _declare(f, opts, aot)
    return _declare(fn, opts, aot)


def pjit(fn: F | None = None, **options: Any) -> Any:
    """Like :func:`jit` with ``parallel=True``: drivers that ``prange`` over independent rows."""
    return jit(fn, parallel=True, **options)


def _declare(fn: Callable[..., Any], opts: dict[str, Any], aot: bool) -> Any:
    with _lock:
        if _numba is not None:  # numba already loaded: a dispatcher at once
            kernel: Any = _numba.njit(**opts)(fn)
        else:
            kernel = Kernel(fn, opts, aot)
        KERNELS.append(kernel)
        return kernel


def _load_numba() -> None:
    """Load numba, give every kernel its dispatcher and put numba's objects where kernels
    look them up (their modules' globals)."""
    global _numba
    with _lock:
        if _numba is not None:
            return
        import numba

        for k in KERNELS:
            if isinstance(k, Kernel):
                k._dispatcher = numba.njit(**k.options)(k.py_func)
        swap = {id(k): k._dispatcher for k in KERNELS if isinstance(k, Kernel)}
        homes = {k.py_func.__module__ for k in KERNELS if isinstance(k, Kernel)}
        lazy_prange = prange
        for name, mod in list(sys.modules.items()):
            if not (name == "monitor" or name.startswith("monitor.") or name in homes):
                continue
            space = getattr(mod, "__dict__", {})
            for key, value in list(space.items()):
                if isinstance(value, Kernel) and id(value) in swap:
                    space[key] = swap[id(value)]
                elif value is lazy_prange:
                    space[key] = numba.prange
        _numba = numba


def numba_loaded() -> bool:
    """Whether this process has loaded numba (through a kernel's first call)."""
    return _numba is not None


def get_num_threads() -> int:
    """numba's thread count for parallel kernels (loads numba)."""
    _load_numba()
    return int(_numba.get_num_threads())


def _dispatcher(k: Any) -> Any:
    return k._dispatcher if isinstance(k, Kernel) else k


def cache_stats() -> dict[str, int]:
    """Kernel signatures loaded from numba's on-disk cache (``hits``) and compiled in this
    process (``misses``) so far, over every kernel of the monitor imported (none while
    numba is not loaded)."""
    built = [d for d in map(_dispatcher, KERNELS) if d is not None]
    hits = sum(sum(d.stats.cache_hits.values()) for d in built)
    misses = sum(sum(d.stats.cache_misses.values()) for d in built)
    return {"kernels": len(KERNELS), "hits": int(hits), "misses": int(misses)}
