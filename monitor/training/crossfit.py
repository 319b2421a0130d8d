"""Cross-fitted residuals: every normal sample judged by a model that never saw it.

A commissioning run is short (20 minutes).  Holding out its last quarter for the thresholds
leaves 5 minutes, all at the end of the warm-up (the hottest oil), and the largest J of so
few windows depends on which end-stop or reversal they happen to contain: on simulated
machines the same 20 minutes gave thresholds five times apart depending on the minutes held
out (docs/benchmarks.md).  Cross-fitting uses all of it instead: the data is cut in blocks
of ``block_n`` samples dealt round-robin to ``folds`` folds (so every fold spans the whole
run and its temperatures); for each fold a DGRNN with the full model's bandwidth is fitted
on the other folds' blocks and predicts the fold's own.  The thresholds then rest on out-of-
sample residuals over the whole run, and each fold model saw less data than the final one.
It is an option (``monitor train --folds K``), not the default: on simulated 20-minute
commissioning runs the bias statistic it enables raised false alarms (the support rule,
``monitor.training.support``, now keeps it off on one recording), and J alone was no better
than with the last quarter held out (docs/benchmarks.md, 2026-11-25); on the outsider's
plant its J thresholds, set on the cold start too, were up to twice as high and missed
most faults (benchmarks/detect_blind/results, 2026-11-28).
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from monitor.io.recording import Recording
from monitor.model.dgrnn import DGRNN
from monitor.model.grnn import GRNN
from monitor.model.modelfile import MonitorModel


def fold_ids(lengths: Sequence[int], folds: int, block_n: int) -> list[np.ndarray]:
    """The fold of every sample: blocks of ``block_n`` samples dealt round-robin over the
    recordings in order (a recording's last, shorter block is a block of its own)."""
    out, first = [], 0
    for n in lengths:
        blocks = np.arange(n) // block_n
        out.append(((blocks + first) % folds).astype(np.int64))
        first += int(blocks[-1]) + 1 if n else 0
    return out


def n_blocks(lengths: Sequence[int], block_n: int) -> int:
    """Blocks ``fold_ids`` deals (the short tail of each recording counts)."""
    return sum(-(-n // block_n) for n in lengths)


def _params(grnn: GRNN) -> dict[str, Any]:
    """The GRNN's constructor arguments (scikit-learn's get_params): fold models are
    thinned and clustered exactly as the full model."""
    names = inspect.signature(GRNN.__init__).parameters
    return {k: getattr(grnn, k) for k in names if k != "self"}


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) of each run of True."""
    edges = np.diff(np.concatenate(([0], mask.astype(np.int8), [0])))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True))


def cross_fitted_residuals(
    model: MonitorModel,
    tables_z: Sequence[np.ndarray],
    recordings: Sequence[Recording],
    folds: int,
    block_n: int,
    residuals: Callable[[MonitorModel, Recording], np.ndarray],
    say: Callable[[str], None] = lambda _m: None,
    lend: Callable[[DGRNN], int] | None = None,
) -> list[np.ndarray]:
    """Out-of-fold residuals (samples, outputs) per recording.

    ``model`` is the model fitted on everything: its spec, normalizer, bandwidth, pattern
    budget and J window are kept; only the patterns differ per fold.  ``tables_z`` are the
    recordings' z-scored variable tables (the training input), ``residuals`` computes a
    model's gated residuals over a recording exactly as the detector does; ``lend`` (if
    any) completes each fold's patterns as the full model's were completed."""
    spec, grnn = model.spec, model.dgrnn.grnn
    ids = fold_ids([len(z) for z in tables_z], folds, block_n)
    out = [np.full((len(z), len(spec.outputs)), np.nan) for z in tables_z]
    for k in range(folds):
        parts = [z[a:b] for z, f in zip(tables_z, ids, strict=True) for a, b in _runs(f != k)]
        parts = [p for p in parts if len(p) > spec.max_lag + 1]
        fold_grnn = GRNN(**{**_params(grnn), "sigma": grnn.sigma_})
        fold_dgrnn = DGRNN(spec, fold_grnn).fit(parts)
        lent = lend(fold_dgrnn) if lend is not None else 0
        fold = MonitorModel(
            fold_dgrnn, model.normalizer, model.window_n, model.threshold, model.j0, model.eps0
        )
        for rec, f, e_out in zip(recordings, ids, out, strict=True):
            mine = f == k
            if mine.any():
                e = residuals(fold, rec)
                e_out[mine] = e[mine]
        say(
            f"  fold {k + 1}/{folds}: {fold_grnn.patterns_.shape[0] - lent} patterns from "
            f"{sum(len(p) for p in parts)} samples"
            + (f", {lent} lent by the reference" if lent else "")
        )
    return out
