"""The one place for numba options, so every kernel is compiled the same way.

``FASTMATH`` lists LLVM fast-math flags explicitly instead of ``fastmath=True``: ``nnan`` and
``ninf`` are left out on purpose, because with them LLVM may assume no NaN/inf exists and
fold away ``np.isnan`` checks and ``inf`` sentinels that the kernels rely on (missing samples
are NaN, excluded neighbours are +inf distances).  The remaining flags only allow reordering
and contraction, which changes results in the last bits, never NaN semantics.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

from numba import get_num_threads, njit, prange

FASTMATH: set[str] = {"nsz", "arcp", "contract", "afn", "reassoc"}

F = TypeVar("F", bound=Callable[..., Any])

__all__ = ["FASTMATH", "cache_stats", "jit", "pjit", "prange", "get_num_threads"]

#: Every kernel compiled through ``jit``/``pjit``, so start-up can say what the cache gave.
KERNELS: list[Any] = []


def jit(fn: F | None = None, **options: Any) -> Any:
    """``njit`` with on-disk caching and the project's fast-math flags (serial kernels)."""
    opts: dict[str, Any] = {"cache": True, "fastmath": FASTMATH, **options}
    if fn is None:
        return lambda f: _registered(njit(**opts)(f))
    return _registered(njit(**opts)(fn))


def _registered(dispatcher: Any) -> Any:
    KERNELS.append(dispatcher)
    return dispatcher


def cache_stats() -> dict[str, int]:
    """Kernel signatures loaded from numba's on-disk cache (``hits``) and compiled in this
    process (``misses``) so far, over every kernel of the monitor imported."""
    hits = sum(sum(k.stats.cache_hits.values()) for k in KERNELS)
    misses = sum(sum(k.stats.cache_misses.values()) for k in KERNELS)
    return {"kernels": len(KERNELS), "hits": int(hits), "misses": int(misses)}


def pjit(fn: F | None = None, **options: Any) -> Any:
    """Like :func:`jit` with ``parallel=True``: drivers that ``prange`` over independent rows."""
    return jit(fn, parallel=True, **options)
