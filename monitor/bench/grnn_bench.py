"""Benchmark 1: GRNN query cost against pyGRNN and a plain numba loop, and its growth.

Three GRNNs on the same patterns, targets and sigma (eq. 11 ``paper`` preset: 8 inputs):

* ``cutoff``: the detector's kernel (``monitor.model.grnn_index``, kd-tree and cut-off);
* ``plain``: the same kernel on a one-leaf index with no cut-off, i.e. the brute-force
  numba loop (every pattern, one exp each) that the detector used before;
* ``pygrnn``: pyGRNN's ``predict`` (scikit-learn's RBF kernel + numpy), one query per call
  as a live detector would call it.

Per query: numba kernels run serially over a batch of real lagged queries inside one
compiled loop (no Python per query), the median of several batches; pyGRNN the median of
single calls.  Per tick of horizon p: ``TickPredictor.predict`` called from Python as the
daemon calls it (p chained queries, eq. 7), median over ticks; pyGRNN's per tick is p times
its per-query time (derived, not run chained).  The error is the largest |cutoff - exact|
over the queries, relative to each output's standard deviation over the patterns.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np

from monitor.bench.data import Sizes, paper_grnn, test_recording, training_runs
from monitor.jit import jit
from monitor.model.dgrnn import DGRNN, TickPredictor, build_training_pairs
from monitor.model.grnn import GRNN
from monitor.model.grnn_index import cutoff_row
from monitor.model.spec import table

Progress = Callable[[str], None]


@jit
def _serial_queries(X, tree, inv2s2, cut, scratch, out):  # pragma: no cover - numba
    for q in range(X.shape[0]):
        cutoff_row(X[q], tree, inv2s2, cut, scratch, out[q])


def _per_query_s(index, X: np.ndarray, sigma: float, budget_s: float) -> float:
    """Median over 5 batches of the mean time per query, serial, in compiled code; each
    batch is spread evenly over the test recording (dense and sparse regions alike)."""
    inv = 0.5 / sigma**2
    scratch = index.scratch()
    out = np.empty((X.shape[0], index.tree[1].shape[1]))
    _serial_queries(X[:2], index.tree, inv, index.cut, scratch, out)  # compile / warm
    t0 = time.perf_counter()
    _serial_queries(X[:20], index.tree, inv, index.cut, scratch, out)
    est = (time.perf_counter() - t0) / 20
    n = int(np.clip(budget_s / 5 / max(est, 1e-9), 20, X.shape[0]))
    step = max(1, X.shape[0] // n)
    runs = []
    for k in range(5):  # each batch spread over the whole recording
        Xb = np.ascontiguousarray(X[(k * 7) % step :: step][:n])
        t0 = time.perf_counter()
        _serial_queries(Xb, index.tree, inv, index.cut, scratch, out)
        runs.append((time.perf_counter() - t0) / Xb.shape[0])
    return float(np.median(runs))


def _pygrnn_per_query_s(P, Y, sigma, X, budget_s: float) -> float | None:
    try:
        from pyGRNN import GRNN as PyGRNN
    except ImportError:  # a test extra; the bench still runs without it
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = PyGRNN(kernel="RBF", sigma=sigma, calibration="None").fit(P, Y[:, 0])
        times = []
        start = time.perf_counter()
        for q in range(X.shape[0]):
            t0 = time.perf_counter()
            ref.predict(X[q : q + 1])
            times.append(time.perf_counter() - t0)
            if len(times) >= 5 and time.perf_counter() - start > budget_s:
                break
    return float(np.median(times))


def _per_tick_s(pred: TickPredictor, Z: np.ndarray, budget_s: float) -> float:
    n = pred.rows_needed
    ends = np.arange(n, Z.shape[0])
    windows = [np.ascontiguousarray(Z[t - n : t]) for t in ends[:: max(1, len(ends) // 4000)]]
    pred.predict(windows[0])
    times: list[float] = []
    start = time.perf_counter()
    for w in windows:
        t0 = time.perf_counter()
        pred.predict(w)
        times.append(time.perf_counter() - t0)
        if len(times) >= 5 and time.perf_counter() - start > budget_s:
            break
    return float(np.median(times))


def measure(sizes: Sizes, say: Progress, budget_s: float = 1.5) -> dict[str, Any]:
    say("GRNN: simulating training data")
    recs = training_runs(sizes.train_s)
    test = test_recording(120.0 if sizes.train_s >= 300 else 30.0, None)
    cells: list[dict[str, Any]] = []
    errors: dict[int, float] = {}
    models: dict[int, dict[str, Any]] = {}
    for n in sizes.patterns:
        say(f"GRNN: fitting the paper preset with {n} patterns")
        model, norm = paper_grnn(recs, n)
        spec = model.spec
        Z = np.ascontiguousarray(norm.transform(table(test, spec.variables), spec.variables))
        X, _, _ = build_training_pairs(spec, Z)
        errors[n] = _max_rel_error(model.grnn, X)
        queries = _per_query(model.grnn, X, budget_s)
        models[n] = {
            "patterns": int(model.grnn.patterns_.shape[0]),
            "inputs": int(X.shape[1]),
            "sigma": float(model.grnn.sigma_),
            "cutoff_c": float(model.grnn.cutoff_index().cut),
        }
        cells += [_cell(model, Z, p, queries, budget_s, n, say) for p in sizes.horizons]
    head = sizes.headline_patterns
    row = next(c for c in cells if c["p"] == sizes.horizons[0] and _near(c["patterns"], head))
    py = row["pygrnn_us_per_query"]
    return {
        "cells": cells,
        "models": {str(k): v for k, v in models.items()},
        "max_rel_error_by_patterns": {str(k): v for k, v in errors.items()},
        "grnn_us_per_query": row["cutoff_us_per_query"],
        "grnn_speedup_vs_numba_loop": row["plain_us_per_query"] / row["cutoff_us_per_query"],
        "grnn_speedup_vs_pygrnn": None if py is None else py / row["cutoff_us_per_query"],
        "grnn_max_rel_error": max(errors.values()),
        "grnn_headline_patterns": row["patterns"],
    }


def _max_rel_error(g: GRNN, X: np.ndarray) -> float:
    """The cut-off GRNN's largest error against the exact one, over the output's std, on
    ``X`` and on far-away queries too: the bound must hold where the data ends."""
    far = X[:: max(1, len(X) // 50)] * 4.0 + 3.0
    Xq = np.ascontiguousarray(np.vstack([X, far]))
    std = g.targets_.std(axis=0)
    err = np.abs(g.predict(Xq, exact=False) - g.predict(Xq, exact=True)) / std
    return float(err.max())


def _per_query(g: GRNN, X: np.ndarray, budget_s: float) -> tuple[float, float, float | None]:
    """Seconds per query: the cut-off GRNN, the plain loop and pyGRNN (None: not installed)."""
    fast_q = _per_query_s(g.cutoff_index(), X, g.sigma_, budget_s)
    plain_q = _per_query_s(g.cutoff_index(exact=True), X, g.sigma_, budget_s)
    py_q = _pygrnn_per_query_s(g.patterns_, g.targets_, g.sigma_, X, budget_s)
    return fast_q, plain_q, py_q


def _cell(
    model: DGRNN,
    Z: np.ndarray,
    p: int,
    queries: tuple[float, float, float | None],
    budget_s: float,
    n_asked: int,
    say: Progress,
) -> dict[str, Any]:
    """One (patterns, horizon) cell: per-query and per-tick times in microseconds."""
    fast_q, plain_q, py_q = queries
    fast_t = _per_tick_s(TickPredictor(model, p), Z, budget_s)
    plain_t = _per_tick_s(TickPredictor(model, p, exact=True), Z, budget_s)
    py_text = "" if py_q is None else f", pyGRNN {py_q * 1e6:.0f} us"
    say(
        f"  {n_asked} patterns, p={p}: cutoff {fast_t * 1e6:.1f} us/tick, plain "
        f"{plain_t * 1e6:.1f} us/tick; per query {fast_q * 1e6:.2f} vs "
        f"{plain_q * 1e6:.1f} us{py_text}"
    )
    return {
        "patterns": int(model.grnn.patterns_.shape[0]),
        "p": p,
        "cutoff_us_per_query": fast_q * 1e6,
        "plain_us_per_query": plain_q * 1e6,
        "pygrnn_us_per_query": None if py_q is None else py_q * 1e6,
        "cutoff_us_per_tick": fast_t * 1e6,
        "plain_us_per_tick": plain_t * 1e6,
        "pygrnn_us_per_tick_derived": None if py_q is None else p * py_q * 1e6,
    }


def _near(n: int, target: int) -> bool:
    return abs(n - target) <= 0.05 * target


def plot(result: dict[str, Any], path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cells = result["cells"]
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.2))
    p1 = min(c["p"] for c in cells)
    base = [c for c in cells if c["p"] == p1]
    n = [c["patterns"] for c in base]
    for key, label, style in (
        ("cutoff_us_per_query", "cut-off kd-tree (this monitor)", "o-"),
        ("plain_us_per_query", "plain numba loop", "s--"),
        ("pygrnn_us_per_query", "pyGRNN", "^:"),
    ):
        ys = [c[key] for c in base]
        if all(y is not None for y in ys):
            a.loglog(n, ys, style, label=label)
    a.set_xlabel("training patterns")
    a.set_ylabel("time per GRNN query (us)")
    a.set_title("query cost vs patterns (8 inputs)")
    a.grid(True, which="both", alpha=0.3)
    a.legend(loc="upper left")
    for size in sorted({c["patterns"] for c in cells}):
        rows = [c for c in cells if c["patterns"] == size]
        ps = [c["p"] for c in rows]
        line = b.loglog(ps, [c["cutoff_us_per_tick"] for c in rows], "o-", label=f"{size} cut-off")
        b.loglog(
            ps,
            [c["plain_us_per_tick"] for c in rows],
            "s--",
            color=line[0].get_color(),
            label=f"{size} plain",
        )
    b.axhline(1000.0, color="k", lw=0.8, ls=":")
    b.text(ps[0], 1100.0, "1 ms (tick goal)", fontsize=8)
    b.set_xlabel("prediction horizon p (queries per tick)")
    b.set_ylabel("time per tick (us)")
    b.set_title("per-tick prediction vs horizon")
    b.grid(True, which="both", alpha=0.3)
    b.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
