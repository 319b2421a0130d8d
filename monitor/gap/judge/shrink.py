"""How far the gap shrinks: before and after on the held-out part, with a block bootstrap.

The blocks are the held-out segments themselves (each a duty-cycle move started from the
measured state, a few seconds long): resampling them keeps the residual's autocorrelation
inside a block, which a sample-wise bootstrap would destroy.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from monitor.gap.fit.score import SegmentSums, gap
from monitor.signals import MEASURED_NAMES

N_BOOT = 400


def resamples(n_segments: int, seed: int = 0, n_boot: int = N_BOOT) -> np.ndarray:
    """Bootstrap index sets (n_boot x n_segments) of held-out segments."""
    rng = np.random.default_rng(seed)
    return rng.integers(0, n_segments, size=(n_boot, n_segments))


def boot_mse(sums: SegmentSums, idx: np.ndarray) -> np.ndarray:
    """Mean squared normalised residual per resample and signal (n_boot x n_signals)."""
    return sums.sq[idx].sum(axis=1) / np.maximum(sums.count[idx].sum(axis=1), 1)


def boot_gap(sums: SegmentSums, idx: np.ndarray, floor: np.ndarray) -> np.ndarray:
    mse = boot_mse(sums, idx)
    return np.maximum(mse - floor, 0.0).sum(axis=1)


def boot_reduction(
    before: SegmentSums, after: SegmentSums, idx: np.ndarray, floor: np.ndarray
) -> np.ndarray:
    g0 = boot_gap(before, idx, floor)
    g1 = boot_gap(after, idx, floor)
    return np.where(g0 > 0, 1.0 - g1 / np.maximum(g0, 1e-300), 0.0)


def finite_or_none(value: float, digits: int) -> float | None:
    """A bootstrap figure for the JSON: rounded to ``digits``, None where nothing was read."""
    return round(float(value), digits) if np.isfinite(value) else None


def _ci(values: np.ndarray) -> list[float]:
    lo, hi = np.percentile(values, [5, 95])
    return [round(float(lo), 5), round(float(hi), 5)]


def shrink_report(
    before: SegmentSums,
    after: SegmentSums,
    idx: np.ndarray,
    floor: np.ndarray,
    regime_rows: Sequence[dict],
    names: Sequence[str] = MEASURED_NAMES,
) -> dict:
    """The JSON ``shrink`` block: NRMSE per signal before/after, reduction, 90 % intervals.

    ``names`` are the columns of the sums (the compared signals)."""
    m0, m1 = before.mse(), after.mse()
    b0, b1 = np.sqrt(boot_mse(before, idx)), np.sqrt(boot_mse(after, idx))
    red = boot_reduction(before, after, idx, floor)
    return {
        "before": {n: round(float(np.sqrt(m0[j])), 5) for j, n in enumerate(names)},
        "after": {n: round(float(np.sqrt(m1[j])), 5) for j, n in enumerate(names)},
        "heldout_reduction": round(1.0 - gap(m1, floor) / gap(m0, floor), 4)
        if gap(m0, floor) > 0
        else 0.0,
        "before_ci90": {n: _ci(b0[:, j]) for j, n in enumerate(names)},
        "after_ci90": {n: _ci(b1[:, j]) for j, n in enumerate(names)},
        "heldout_reduction_ci90": _ci(red),
        "regimes": list(regime_rows),
        "noise_floor_nrmse": {n: round(float(np.sqrt(floor[j])), 5) for j, n in enumerate(names)},
    }
