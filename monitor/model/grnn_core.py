"""Eq. 4 as functions, the estimator's building blocks: the numba kernels (squared distances,
nearest pattern, leave-one-out errors, greedy thinning), input validation, and the public
functions (prediction, clustering, LOO errors, thinning).  The scikit-learn style estimator
``GRNN`` in ``monitor.model.grnn`` fits with them; the module docstring there has the method.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from monitor.errors import ConfigError, InputFileError
from monitor.jit import get_num_threads, jit, pjit, prange
from monitor.model.grnn_index import exact_index, predict_cutoff


@dataclass(frozen=True)
class PatternSet:
    """A fitted GRNN's patterns: inputs (z-scored), targets, members per pattern and the
    time index of each pattern's seed row."""

    patterns: np.ndarray
    targets: np.ndarray
    counts: np.ndarray
    index: np.ndarray


@dataclass(frozen=True)
class Bandwidth:
    """The fitted sigma and how it was chosen (``fixed`` or ``loo``, the leave-one-out
    error at it, NaN when fixed, and the temporal neighbours left out)."""

    sigma: float
    rule: str
    loo_error: float
    exclude_neighbours: int


SIGMA_RULES = ("loo", "fixed")
THINNING_RULES = ("none", "stride", "min_distance")

# Cap on the LOO distance matrix (queries x patterns, float64): 16 M entries = 128 MB.
_LOO_MAX_ENTRIES = 16_000_000


# --------------------------------------------------------------------------- kernels


def n_chunks() -> int:
    """Work chunks for the parallel drivers (a few per thread, for load balance)."""
    return 4 * get_num_threads()


@pjit
def _sqdist(Q, P):  # pragma: no cover - numba
    """Squared distances query x pattern (sigma-free, so the LOO search computes them once)."""
    nq, nf = Q.shape
    n = P.shape[0]
    D = np.empty((nq, n))
    for q in prange(nq):
        for i in range(n):
            acc = 0.0
            for f in range(nf):
                diff = Q[q, f] - P[i, f]
                acc += diff * diff
            D[q, i] = acc
    return D


@pjit
def _nearest(X, P, nchunk):  # pragma: no cover - numba
    """Index of the nearest pattern for every row of X (first one on ties).

    Exact, but quicker than a full scan: the previous row's answer is the first guess
    (consecutive rows are close), and a pattern's sum stops once it exceeds the best so far
    (a sum of squares only grows, rounding included)."""
    nq, n, nf = X.shape[0], P.shape[0], P.shape[1]
    out = np.zeros(nq, dtype=np.int64)
    if n == 0:
        return out
    nchunk = max(1, min(nq, nchunk))
    for c in prange(nchunk):
        k = 0
        for q in range(c * nq // nchunk, (c + 1) * nq // nchunk):
            best = 0.0
            for f in range(nf):
                diff = X[q, f] - P[k, f]
                best += diff * diff
            if best != best:  # a NaN in the row: no pattern is nearer, the full scan's 0
                k = 0
                out[q] = 0
                continue
            for i in range(n):
                acc = 0.0
                for f in range(nf):
                    diff = X[q, f] - P[i, f]
                    acc += diff * diff
                    if acc > best:
                        break
                if acc < best or (acc == best and i < k):
                    best = acc
                    k = i
            out[q] = k
    return out


@pjit
def _loo_errors(D, Xq, qrow, lo, hi, assign, X, Y, counts, xsums, ysums, inv2s2, nchunk):
    """Per-query squared error (mean over outputs) with the query's temporal neighbours
    (rows lo[q]..hi[q]-1) taken out of the clusters they belong to.

    ``D`` holds squared distances from the queries to the full clusters' centroids; a
    cluster that loses members gets its centroid and distance recomputed.  Counts are
    integers held in float64, so removing and restoring them is exact; sums are restored by
    copying, never by adding back.
    """  # pragma: no cover - numba
    nq, n = D.shape
    nf, nout = X.shape[1], Y.shape[1]
    err = np.empty(nq)
    nchunk = max(1, min(nq, nchunk))
    logc = np.empty(n)
    for i in range(n):
        logc[i] = math.log(counts[i]) if counts[i] > 0.0 else -np.inf
    for c in prange(nchunk):
        cnt = counts.copy()
        xs = xsums.copy()
        ys = ysums.copy()
        touched = np.zeros(n, dtype=np.bool_)
        dbuf = np.empty(n)
        num = np.empty(nout)
        for q in range(c * nq // nchunk, (c + 1) * nq // nchunk):
            for j in range(lo[q], hi[q]):
                a = assign[j]
                if a >= 0:
                    touched[a] = True
                    cnt[a] -= 1.0
                    for f in range(nf):
                        xs[a, f] -= X[j, f]
                    for k in range(nout):
                        ys[a, k] -= Y[j, k]
            dmin = np.inf
            for i in range(n):
                d = np.inf
                if cnt[i] > 0.5:
                    d2 = D[q, i]
                    if touched[i]:
                        d2 = 0.0
                        for f in range(nf):
                            diff = Xq[q, f] - xs[i, f] / cnt[i]
                            d2 += diff * diff
                    d = d2 * inv2s2 - (math.log(cnt[i]) if touched[i] else logc[i])
                    if d < dmin:
                        dmin = d
                dbuf[i] = d
            if dmin < np.inf:
                for k in range(nout):
                    num[k] = 0.0
                den = 0.0
                for i in range(n):
                    # exp() below -746 is exactly 0.0: such a cluster adds nothing.
                    if dbuf[i] - dmin < 746.0:
                        # Weight c_i exp(-d_i) times the member mean ys_i / c_i.
                        w = math.exp(dmin - dbuf[i])
                        den += w
                        for k in range(nout):
                            num[k] += w * ys[i, k] / cnt[i]
                acc = 0.0
                for k in range(nout):
                    e = num[k] / den - Y[qrow[q], k]
                    acc += e * e
                err[q] = acc / nout
            else:
                err[q] = np.nan  # every cluster is a neighbour: this query cannot be scored
            for j in range(lo[q], hi[q]):
                a = assign[j]
                if a >= 0 and touched[a]:
                    touched[a] = False
                    cnt[a] = counts[a]
                    for f in range(nf):
                        xs[a, f] = xsums[a, f]
                    for k in range(nout):
                        ys[a, k] = ysums[a, k]
    return err


@jit
def _greedy_min_distance(X, r2, max_keep):  # pragma: no cover - numba
    """Indices (time order) kept by greedy thinning, and False if more than max_keep."""
    n, nf = X.shape
    keep = np.empty(min(n, max_keep + 1), dtype=np.int64)
    k = 0
    for i in range(n):
        ok = True
        # Newest kept first: consecutive 100 Hz rows are close, so this usually breaks early.
        for j in range(k - 1, -1, -1):
            kk = keep[j]
            acc = 0.0
            for f in range(nf):
                diff = X[i, f] - X[kk, f]
                acc += diff * diff
                if acc > r2:
                    break  # a sum of squares only grows, rounding included: too far
            if acc <= r2:
                ok = False
                break
        if ok:
            if k == max_keep:
                return keep[:0].copy(), False
            keep[k] = i
            k += 1
    return keep[:k].copy(), True


# --------------------------------------------------------------------------- validation


def _as_matrix(a: Any, name: str, *, cls: type[Exception] = InputFileError) -> np.ndarray:
    arr = np.asarray(a, dtype=np.float64)
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2:
        raise cls(f"{name} must be 2-D (rows, columns), got shape {arr.shape}")
    return np.ascontiguousarray(arr)


def _require_finite(arr: np.ndarray, name: str) -> None:
    bad = ~np.isfinite(arr)
    if bad.any():
        row = int(np.argwhere(bad)[0][0])
        raise InputFileError(
            f"{name} has a non-finite value (NaN or inf) in row {row}; training patterns "
            "must be complete (drop rows with missing samples first)"
        )


def _check_sigma(sigma: float) -> float:
    s = float(sigma)
    if not (math.isfinite(s) and s > 0.0 and math.isfinite(0.5 / (s * s))):
        raise ConfigError(f"sigma must be a positive finite number, got {s:g}")
    return s


def _check_time_index(time_index: Any, n: int) -> np.ndarray:
    if time_index is None:
        return np.arange(n, dtype=np.int64)
    idx = np.asarray(time_index)
    if idx.shape != (n,) or not np.issubdtype(idx.dtype, np.integer):
        raise ConfigError(f"time_index must be {n} integers (one per pattern), got {idx.shape}")
    idx = idx.astype(np.int64)
    if n > 1 and np.any(np.diff(idx) <= 0):
        raise ConfigError("time_index must be strictly increasing (patterns in time order)")
    return idx


# --------------------------------------------------------------------------- public functions


def _check_counts(counts: Any, n: int) -> np.ndarray:
    if counts is None:
        return np.ones(n)
    c = np.asarray(counts, dtype=np.float64)
    if c.shape != (n,) or not np.all(np.isfinite(c)) or np.any(c < 1) or np.any(c != np.round(c)):
        raise InputFileError(f"counts must be {n} whole numbers >= 1 (one per pattern)")
    return c


def grnn_predict(
    X: Any, patterns: Any, targets: Any, sigma: float, counts: Any = None
) -> np.ndarray:
    """Eq. 4 for every row of ``X``; returns (n_queries, n_outputs).

    ``patterns`` (n_patterns, n_features) must be finite; a query row with NaN gives NaN.
    ``counts`` (members per pattern, default 1 each) gives Specht's clustered form.
    """
    P = _as_matrix(patterns, "patterns")
    Y = _as_matrix(targets, "targets")
    Xq = _as_matrix(X, "X")
    if P.shape[0] != Y.shape[0] or P.shape[0] == 0:
        raise InputFileError(
            f"patterns ({P.shape[0]} rows) and targets ({Y.shape[0]} rows) must match and be"
            " non-empty"
        )
    if Xq.shape[1] != P.shape[1]:
        raise InputFileError(f"X has {Xq.shape[1]} features, the patterns have {P.shape[1]}")
    _require_finite(P, "patterns")
    _require_finite(Y, "targets")
    s = _check_sigma(sigma)
    counts = _check_counts(counts, P.shape[0])
    return predict_cutoff(exact_index(P, Y, counts), Xq, s, n_chunks())


def cluster(X: Any, Y: Any, seeds: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Specht's clusters: every row of X joins its nearest seed (a kept row).

    Returns (assign, counts, centroids, mean targets): ``assign[j]`` is row j's cluster; a
    cluster is represented by its members' mean input and mean target, so a locally linear
    map keeps its value (the seed itself is the first row greedy thinning met, usually at
    one end of its members).  A seed with no member (impossible when the seeds are rows of
    X) would get count 0.
    """
    Xa, Ya, P = _as_matrix(X, "X"), _as_matrix(Y, "Y"), _as_matrix(seeds, "seeds")
    assign = _nearest(Xa, P, n_chunks())
    counts = np.bincount(assign, minlength=P.shape[0]).astype(np.float64)
    xs = np.zeros(P.shape)
    np.add.at(xs, assign, Xa)
    ys = np.zeros((P.shape[0], Ya.shape[1]))
    np.add.at(ys, assign, Ya)
    with np.errstate(invalid="ignore"):
        return assign, counts, xs / counts[:, None], ys / counts[:, None]


def _neighbour_ranges(tidx: np.ndarray, rows: np.ndarray, m: int) -> tuple[np.ndarray, ...]:
    lo = np.searchsorted(tidx, tidx[rows] - m, side="left").astype(np.int64)
    hi = np.searchsorted(tidx, tidx[rows] + m, side="right").astype(np.int64)
    return lo, hi


def loo_errors(
    rows: Any,
    X: Any,
    Y: Any,
    assign: Any,
    sigma: float,
    exclude_neighbours: int = 0,
    time_index: Any = None,
) -> np.ndarray:
    """Leave-one-out squared error (mean over outputs) for the training rows ``rows``.

    Row j of (X, Y) is a member of cluster ``assign[j]`` (-1: of none); a cluster sits at
    its members' mean input, with their mean target and their count as weight.  For each
    query row, every row within ``exclude_neighbours`` samples of it in time
    (``time_index``, default 0..n-1) leaves its cluster first, so neither the query nor its
    near copies predict it.  With one member per cluster this is plain LOO of eq. 4 over
    the patterns more than m samples away.  A query whose every cluster empties gets NaN.
    """
    Xa, Ya = _as_matrix(X, "X"), _as_matrix(Y, "Y")
    tidx = _check_time_index(time_index, Xa.shape[0])
    q = np.asarray(rows, dtype=np.int64)
    a = np.asarray(assign, dtype=np.int64)
    if a.shape != (Xa.shape[0],) or np.any(a < -1):
        raise ConfigError(f"assign must hold a cluster index or -1 for each of {Xa.shape[0]} rows")
    s = _check_sigma(sigma)
    args = _loo_setup(q, Xa, Ya, tidx, int(exclude_neighbours), a)
    return _loo_errors(*args, 0.5 / (s * s), n_chunks())


def _loo_setup(q, X, Y, tidx, m, assign) -> tuple:
    """The sigma-free part of the LOO: cluster sums, neighbour ranges, distances."""
    member = assign >= 0
    n = int(assign.max()) + 1 if member.any() else 0
    counts = np.bincount(assign[member], minlength=n).astype(np.float64)
    xsums = np.zeros((n, X.shape[1]))
    np.add.at(xsums, assign[member], X[member])
    ysums = np.zeros((n, Y.shape[1]))
    np.add.at(ysums, assign[member], Y[member])
    lo, hi = _neighbour_ranges(tidx, q, m)
    with np.errstate(invalid="ignore"):
        centroids = np.ascontiguousarray(xsums / counts[:, None])
    Xq = np.ascontiguousarray(X[q])
    D = _sqdist(Xq, centroids)
    return D, Xq, q, lo, hi, assign, X, Y, counts, xsums, ysums


def thin_min_distance(X: Any, radius: float, max_keep: int | None = None) -> np.ndarray | None:
    """Greedy thinning in time order: keep a row only if farther than ``radius`` from every
    row kept so far.  Returns kept indices, or None when more than ``max_keep`` would be kept.
    """
    A = _as_matrix(X, "X")
    cap = A.shape[0] if max_keep is None else int(max_keep)
    keep, ok = _greedy_min_distance(A, float(radius) ** 2, cap)
    return keep if ok else None
