"""What a statistic's threshold rests on: independent windows, regimes, the rate it implies.

A statistic judged on overlapping windows (J over 30 s, B over 60 s, updated every sample) is
strongly correlated from one sample to the next: an hour of it holds about as much evidence
as its number of non-overlapping windows, fewer when neighbouring windows still move
together (a long hold, the oil warming).  The held-out data is therefore counted in windows
one statistic window long, their largest values, and the lag-1 correlation of those maxima
shrinks the count to the effective number of independent windows (the AR(1) variance
inflation, n (1 - rho) / (1 + rho)).  What the threshold then implies is a Poisson count: k
windows above it in n_eff windows of ``window_s`` seconds, a false-alarm rate of k per
n_eff windows' hours, with its one-sided 95 % upper bound (chi-square, as the detect_blind
and eval-sim scores state theirs).  With k = 0 the bound is -ln(0.05) = 3.0 false alarms
per such span: 20 minutes of commissioning can show no rate below about 9 per hour.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

#: Spool command (%) beyond which a sample counts as raising / lowering (the isolation's).
MOVE_PCT = 5.0


def window_maxima(series: np.ndarray, window_n: int) -> np.ndarray:
    """The largest value of each non-overlapping window of ``window_n`` samples in which at
    least half the samples were judged (finite); NaN for the other windows."""
    x = np.asarray(series, dtype=np.float64)
    n = len(x) // window_n
    if n == 0:
        return np.zeros(0)
    blocks = x[: n * window_n].reshape(n, window_n)
    judged = np.isfinite(blocks).sum(axis=1) * 2 >= window_n
    out = np.full(n, np.nan)
    if judged.any():
        out[judged] = np.nanmax(blocks[judged], axis=1)
    return out


def independent_windows(maxima: Sequence[np.ndarray]) -> tuple[int, float, float]:
    """(windows, rho, effective independent windows) over the parts' window maxima: rho is
    the lag-1 correlation of neighbouring judged windows within a part, each part about its
    own mean (parts at other conditions differ in level, which is not correlation in
    time); 0 when too few to tell, never below 0.  n_eff = n (1 - rho) / (1 + rho)."""
    n = int(sum(np.isfinite(m).sum() for m in maxima))
    a_parts, b_parts = [], []
    for m in maxima:
        ok = np.isfinite(m[:-1]) & np.isfinite(m[1:])
        if ok.sum() < 2:
            continue
        mean = float(np.nanmean(m))
        a_parts.append(m[:-1][ok] - mean)
        b_parts.append(m[1:][ok] - mean)
    rho = 0.0
    if sum(len(a) for a in a_parts) >= 3:
        a, b = np.concatenate(a_parts), np.concatenate(b_parts)
        den = float(np.sqrt(np.sum(a * a) * np.sum(b * b)))
        rho = max(0.0, float(np.sum(a * b)) / den) if den > 0 else 0.0
    return n, rho, n * (1.0 - rho) / (1.0 + rho)


def rate_upper95(count: int, hours: float) -> float:
    """One-sided 95 % upper bound on a Poisson rate per hour, ``count`` events seen in
    ``hours`` (inf without hours)."""
    from scipy.stats import chi2

    if not hours > 0:
        return math.inf
    return float(chi2.ppf(0.95, 2 * (count + 1)) / 2.0 / hours)


def implied_rate(maxima: Sequence[np.ndarray], threshold: float, window_s: float) -> dict[str, Any]:
    """Independent windows and the false-alarm rate the threshold implies on them: windows
    whose largest value exceeds it, per effective hour, and the 95 % upper bound."""
    n, rho, n_eff = independent_windows(maxima)
    above = int(sum(np.sum(m[np.isfinite(m)] > threshold) for m in maxima))
    hours = n_eff * window_s / 3600.0
    seen = above / hours if hours > 0 else None
    upper = rate_upper95(above, hours)
    return {
        "independent_windows": round(n_eff, 1),
        "window_correlation": round(rho, 3),
        "windows_above": above,
        "false_alarms_per_h": None if seen is None else round(seen, 3),
        "false_alarms_per_h_upper95": round(upper, 3) if math.isfinite(upper) else None,
    }


def spool_shares(spool_pct: Sequence[np.ndarray], judged: Sequence[np.ndarray]) -> dict[str, float]:
    """Share of the judged samples holding, raising and lowering (by the spool command)."""
    s = np.concatenate([np.asarray(x)[j] for x, j in zip(spool_pct, judged, strict=True)])
    if s.size == 0:
        return {}
    return {
        "hold": round(float(np.mean(np.abs(s) <= MOVE_PCT)), 3),
        "raise": round(float(np.mean(s > MOVE_PCT)), 3),
        "lower": round(float(np.mean(s < -MOVE_PCT)), 3),
    }
