"""Residuals of a simulation against the recording, normalised per signal.

The compared signals are PP, PA, PB and QP, plus the rod velocity when RodPos is measured
(``compared``).  Every signal's residual is divided by the measured signal's standard
deviation over the recording (NRMSE).  The *gap* of a model is the part of the mean
squared normalised residual above the sensor noise, summed over the signals: zero for a
perfect simulator, whatever the noise.  Per-segment sums let the bootstrap resample
segments cheaply.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from monitor.gap.data.prepare import ROD_VEL, Prepared
from monitor.gap.data.segments import Segment
from monitor.signals import MEASURED_NAMES


def compared(prep: Prepared) -> tuple[str, ...]:
    """The signals a simulation is scored on: the four measured ones first."""
    return (*MEASURED_NAMES, ROD_VEL) if ROD_VEL in prep.meas else MEASURED_NAMES


def normalised(prep: Prepared, pred: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """(simulated - measured) / std(measured) per signal on the grid (NaN where unknown
    or not compared, ``prep.unscored``)."""
    out = {n: (pred[n] - prep.meas[n]) / prep.scale[n] for n in compared(prep)}
    if prep.unscored is not None:
        for v in out.values():
            v[prep.unscored] = np.nan
    return out


def noise_floor(prep: Prepared) -> np.ndarray:
    """Mean squared normalised residual a perfect simulator leaves: the sensor noise."""
    return np.array([prep.noise_var[n] / prep.scale[n] ** 2 for n in compared(prep)])


def stacked(prep: Prepared, segments: Sequence[Segment], pred: dict[str, np.ndarray]) -> np.ndarray:
    """All scored normalised residuals of ``segments`` in one vector (missing -> 0)."""
    r = normalised(prep, pred)
    parts = [r[n][seg.scored] for seg in segments for n in r]
    return np.nan_to_num(np.concatenate(parts))


@dataclass
class SegmentSums:
    """Per segment (rows) and signal (columns): sum of squared normalised residual, count."""

    sq: np.ndarray
    count: np.ndarray

    def mse(self, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        return self.sq[rows].sum(axis=0) / np.maximum(self.count[rows].sum(axis=0), 1)


def segment_sums(
    prep: Prepared,
    segments: Sequence[Segment],
    pred: dict[str, np.ndarray],
    filt: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None,
) -> SegmentSums:
    """Sums per segment and signal; ``filt`` maps a segment's residual to (filtered residual,
    mask of the samples that count), e.g. the base-mismatch smoothing (``basemis.smooth``)."""
    r = normalised(prep, pred)
    sq = np.zeros((len(segments), len(r)))
    count = np.zeros_like(sq)
    for i, seg in enumerate(segments):
        for j, n in enumerate(r):
            v = r[n][seg.scored]
            v, ok = filt(v) if filt is not None else (v, np.isfinite(v))
            sq[i, j] = float(np.sum(v[ok] ** 2))
            count[i, j] = ok.sum()
    return SegmentSums(sq, count)


def gap(mse: np.ndarray, floor: np.ndarray) -> float:
    """Summed excess of the mean squared normalised residual over the noise floor."""
    return float(np.sum(np.maximum(mse - floor, 0.0)))


def reduction(before: float, after: float) -> float:
    """Fraction of the gap removed (negative when the model got worse)."""
    return 0.0 if before <= 0.0 else 1.0 - after / before


def effective_n(prep: Prepared, segments: Sequence[Segment], pred: dict[str, np.ndarray]) -> float:
    """Sample size corrected for autocorrelation: n (1 - rho) / (1 + rho), rho at lag 1."""
    r = normalised(prep, pred)
    total = 0.0
    for n in r:
        num = den = 0.0
        count = 0
        for seg in segments:
            v = np.nan_to_num(r[n][seg.scored])
            v = v - v.mean() if v.size else v
            num += float(np.dot(v[1:], v[:-1]))
            den += float(np.dot(v, v))
            count += v.size
        rho = min(max(num / den, 0.0), 0.999) if den > 0 else 0.0
        total += count * (1 - rho) / (1 + rho)
    return max(total, 1.0)
