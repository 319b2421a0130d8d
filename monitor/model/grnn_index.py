"""Eq. 4 with a cut-off radius on a kd-tree: the GRNN the detector runs, live and offline.

Brute force visits every pattern with one exp each.  But with
the shift of ``monitor.model.grnn`` the nearest pattern weighs 1 and a pattern at scaled distance
d_i (d_i = |x - x_i|^2 / (2 sigma^2)) weighs exp(d_min - d_i), so patterns far beyond the
nearest one cannot move the output.  This module sums only the patterns with
d_i <= d_min + c and proves how little the others could change.

Clustered patterns (``monitor.model.grnn``: pattern i stands for c_i training rows) weigh
c_i exp(-d_i) = exp(-(d_i - ln c_i)); everything below holds with d_i read as the
log-weighted distance d_i - ln c_i (1 member each: ln 1 = 0, plain eq. 4).

Error bound.  Let S be the summed patterns (the nearest one is always in S, so the summed
weight D >= 1), M the weight left out, ŷ_S the output over S and ŷ eq. 4 over all n
patterns.  Then for each output k

    ŷ_k - ŷ_S,k = sum_{i not in S} w_i (y_ik - ŷ_S,k) / (D + M),

and since every left-out w_i < exp(-c), M < n exp(-c), and ŷ_S,k lies within the range of
the targets, |ŷ_k - ŷ_S,k| < n exp(-c) (max_k y - min_k y) / D <= n exp(-c) range_k.
Choosing

    c = ln(n * max_k(range_k / std_k) / rel_tol)

(std_k the standard deviation of target k over the patterns) bounds the error by
rel_tol * std_k for every output and every query, near or far (``rel_tol`` = 1e-6 by
default; up to float64 rounding of the sums).  The bound does not depend on the query, so it
holds for a query far from every pattern (``d_min`` large) exactly as for one among them;
a query with NaN gives NaN outputs, as the exact path does.

Search.  A kd-tree (median split on the widest box side, leaves of ``leaf_size`` patterns)
is built once when a model is loaded, as plain arrays that numba kernels read: patterns and
targets permuted into tree order, each node's bounding box, its largest ln c_i, its pattern
range and children.  A depth-first walk visits the nearer child first, keeps the smallest
distance found so far (``d_best``, always >= the final ``d_min``) and skips a node whose box
distance minus its largest ln c_i exceeds ``d_best + c``: everything skipped is beyond
``d_min + c``, so the bound above holds.  One
pass gives the weights for all outputs; distances and sums are float64 (the walk touches a
few dozen patterns per query on the shipped model, so float32 would save little and would
need its own rounding term in the bound).

The exact path is the same kernel on a one-leaf "tree" with c = inf: every pattern in file
order, every weight (what ``monitor.model.grnn_core.grnn_predict`` and ``exact=True`` run).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from monitor.errors import ConfigError
from monitor.jit import jit, pjit, prange

#: Default bound on the output error, relative to each output's standard deviation.
REL_TOL = 1e-6
LEAF_SIZE = 16


@dataclass(frozen=True)
class CutoffIndex:
    """A kd-tree over a GRNN's patterns plus the cut-off ``cut`` (scaled distance units).

    ``tree`` is the tuple the numba kernels take: (patterns, targets, log_counts, box_lo,
    box_hi, node_max_log_count, node_start, node_end, node_left, node_right), patterns,
    targets and log counts in tree order.
    """

    tree: tuple[np.ndarray, ...]
    cut: float
    rel_tol: float
    depth: int

    @property
    def n_patterns(self) -> int:
        return int(self.tree[0].shape[0])

    def scratch(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per-thread buffers of the kernel: node stack, candidate distances and rows."""
        n = self.n_patterns
        return (np.empty(2 * self.depth + 4, dtype=np.int64), np.empty(n), np.empty(n, np.int64))


def cutoff_for(targets: np.ndarray, rel_tol: float = REL_TOL) -> float:
    """The c of the module docstring for these targets (n rows, outputs as columns)."""
    if not (0.0 < rel_tol < 1.0):
        raise ConfigError(f"rel_tol must be in (0, 1), got {rel_tol}")
    Y = np.asarray(targets, dtype=np.float64).reshape(targets.shape[0], -1)
    spread = np.ptp(Y, axis=0)
    std = Y.std(axis=0)
    # A constant target (std 0, range 0) is never wrong: ratio 1 keeps c finite.
    ratio = np.where(std > 0, spread / np.where(std > 0, std, 1.0), 1.0)
    return math.log(Y.shape[0] * max(1.0, float(ratio.max())) / rel_tol)


def _log_counts(counts: np.ndarray | None, n: int) -> np.ndarray:
    return np.zeros(n) if counts is None else np.log(np.asarray(counts, dtype=np.float64))


def build_index(
    patterns: np.ndarray,
    targets: np.ndarray,
    counts: np.ndarray | None = None,
    rel_tol: float = REL_TOL,
    leaf_size: int = LEAF_SIZE,
) -> CutoffIndex:
    """kd-tree over ``patterns`` (n, features) with their ``targets`` (n, outputs) and
    member ``counts`` (n,; default 1 each)."""
    P = np.ascontiguousarray(patterns, dtype=np.float64)
    Y = np.ascontiguousarray(targets, dtype=np.float64).reshape(P.shape[0], -1)
    LW = _log_counts(counts, P.shape[0])
    if leaf_size < 1:
        raise ConfigError(f"leaf_size must be >= 1, got {leaf_size}")
    n = P.shape[0]
    order = np.arange(n)
    start, end, left, right = [0], [n], [-1], [-1]
    depth = {0: 0}
    todo = [0]
    while todo:  # breadth of the tree is O(n / leaf_size): a Python loop is fine at load
        node = todo.pop()
        s, e = start[node], end[node]
        if e - s <= leaf_size:
            continue
        rows = order[s:e]
        dim = int(np.argmax(np.ptp(P[rows], axis=0)))
        mid = (e - s) // 2
        order[s:e] = rows[np.argpartition(P[rows, dim], mid)]
        for a, b in ((s, s + mid), (s + mid, e)):
            child = len(start)
            start.append(a)
            end.append(b)
            left.append(-1)
            right.append(-1)
            depth[child] = depth[node] + 1
            todo.append(child)
            if a == s:
                left[node] = child
            else:
                right[node] = child
    Ps, Ys = np.ascontiguousarray(P[order]), np.ascontiguousarray(Y[order])
    LWs = np.ascontiguousarray(LW[order])
    spans = list(zip(start, end, strict=True))
    lo = np.array([Ps[a:b].min(axis=0) for a, b in spans])
    hi = np.array([Ps[a:b].max(axis=0) for a, b in spans])
    lwmax = np.array([LWs[a:b].max() for a, b in spans])
    as_int = lambda v: np.asarray(v, dtype=np.int64)  # noqa: E731
    nodes = (as_int(start), as_int(end), as_int(left), as_int(right))
    tree = (Ps, Ys, LWs, lo, hi, lwmax, *nodes)
    return CutoffIndex(tree, cutoff_for(Y, rel_tol), rel_tol, max(depth.values()))


def exact_index(
    patterns: np.ndarray, targets: np.ndarray, counts: np.ndarray | None = None
) -> CutoffIndex:
    """One leaf in file order and c = inf: the kernel then is brute-force eq. 4."""
    P = np.ascontiguousarray(patterns, dtype=np.float64)
    Y = np.ascontiguousarray(targets, dtype=np.float64).reshape(P.shape[0], -1)
    LW = _log_counts(counts, P.shape[0])
    n = P.shape[0]
    one = lambda v: np.array([v], dtype=np.int64)  # noqa: E731
    box = (P.min(axis=0)[None], P.max(axis=0)[None], np.array([LW.max()]))
    tree = (P, Y, LW, *box, one(0), one(n), one(-1), one(-1))
    return CutoffIndex(tree, math.inf, 0.0, 0)


@jit
def _box_dist(x, lo, hi, node):  # pragma: no cover - numba
    acc = 0.0
    for f in range(x.shape[0]):
        v = x[f]
        if v < lo[node, f]:
            diff = lo[node, f] - v
            acc += diff * diff
        elif v > hi[node, f]:
            diff = v - hi[node, f]
            acc += diff * diff
    return acc


@jit
def cutoff_row(x, tree, inv2s2, cut, scratch, out):  # pragma: no cover - numba
    """Eq. 4 for query ``x`` into ``out`` (n_outputs,) over the patterns within the cut-off."""
    P, Y, LW, lo, hi, lwmax, start, end, left, right = tree
    stack, cand_d, cand_i = scratch
    nf = P.shape[1]
    nout = Y.shape[1]
    for f in range(nf):
        if np.isnan(x[f]):
            for k in range(nout):
                out[k] = np.nan
            return
    best = np.inf
    m = 0
    sp = 1
    stack[0] = 0
    while sp > 0:
        sp -= 1
        node = stack[sp]
        if _box_dist(x, lo, hi, node) * inv2s2 - lwmax[node] > best + cut:
            continue  # the walk found a nearer pattern since this node was pushed
        a = left[node]
        if a < 0:
            for i in range(start[node], end[node]):
                acc = 0.0
                for f in range(nf):
                    diff = x[f] - P[i, f]
                    acc += diff * diff
                d = acc * inv2s2 - LW[i]
                if d <= best + cut:
                    cand_d[m] = d
                    cand_i[m] = i
                    m += 1
                    if d < best:
                        best = d
            continue
        b = right[node]
        da = _box_dist(x, lo, hi, a) * inv2s2 - lwmax[a]
        db = _box_dist(x, lo, hi, b) * inv2s2 - lwmax[b]
        if da > db:  # push the farther child first: the nearer one is walked next
            a, b, da, db = b, a, db, da
        if db <= best + cut:
            stack[sp] = b
            sp += 1
        if da <= best + cut:
            stack[sp] = a
            sp += 1
    if not best < np.inf:  # inf distances (overflowing input): nothing to weigh, as exact
        for k in range(nout):
            out[k] = np.nan
        return
    for k in range(nout):
        out[k] = 0.0
    den = 0.0
    limit = best + cut
    for j in range(m):
        d = cand_d[j]
        if d <= limit:
            w = math.exp(best - d)  # <= 1, exactly 1 for the heaviest pattern
            den += w
            i = cand_i[j]
            for k in range(nout):
                out[k] += w * Y[i, k]
    for k in range(nout):
        out[k] /= den


@pjit
def _predict_rows(X, tree, inv2s2, cut, stack_len, nchunk):  # pragma: no cover - numba
    nq = X.shape[0]
    n = tree[0].shape[0]
    out = np.empty((nq, tree[1].shape[1]))
    nchunk = max(1, min(nq, nchunk))
    for c in prange(nchunk):
        scratch = (np.empty(stack_len, np.int64), np.empty(n), np.empty(n, np.int64))
        for q in range(c * nq // nchunk, (c + 1) * nq // nchunk):
            cutoff_row(X[q], tree, inv2s2, cut, scratch, out[q])
    return out


def predict_cutoff(index: CutoffIndex, X: np.ndarray, sigma: float, nchunk: int) -> np.ndarray:
    """Eq. 4 within the cut-off for every row of ``X`` (validated by the caller)."""
    Xq = np.ascontiguousarray(X, dtype=np.float64)
    inv = 0.5 / (sigma * sigma)
    return _predict_rows(Xq, index.tree, inv, index.cut, 2 * index.depth + 4, nchunk)
