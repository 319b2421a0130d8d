"""Health index and prognosis per machine, from logs.parquet rows.

The health index of a log is its largest alarm level (1.0 is the alarm threshold).  The
trend is Theil-Sen (median of pairwise slopes, robust to a few odd logs) over the machine's
last ``k`` judged logs, in index per log; the prognosis is the number of logs until the fitted
line reaches 1.0, with the interval from the slope's confidence bounds, or no upward trend.

A rise counts as a trend only when Kendall's tau says it is unlikely to be day-to-day
scatter (one-sided p < ``TREND_P``): three rising logs of a healthy machine happen by chance
one time in six, and a service visit planned on them is wasted.  So a trend needs at least
four judged logs, and a wearing machine's prognosis comes after four logs of rise.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

#: One-sided p-value of Kendall's tau below which a rise is a trend.
TREND_P = 0.10


@dataclass(frozen=True)
class Prognosis:
    machine: str
    logs: int  # judged logs in the fit
    last_index: float | None  # the newest judged log's max J / eps0
    slope_per_log: float | None
    logs_to_alarm: float | None  # None: no upward trend (or too few logs)
    logs_to_alarm_range: tuple[float, float] | None  # from the slope's 90 % bounds (inf: none)
    p_value: float | None = None  # Kendall's tau, one-sided, of a rise (None: not tested)

    @property
    def text(self) -> str:
        if self.last_index is not None and self.last_index >= 1.0:
            return "at or above 1.0"  # the newest log alarmed: no forecast needed
        if self.logs_to_alarm is None:
            if self.logs < 3:
                return "too few judged logs"
            if self.p_value is not None and self.p_value >= TREND_P:
                return f"no clear upward trend (p {self.p_value:.2f})"
            return "no upward trend"
        if self.logs_to_alarm <= 0:
            return "due now (the trend line is at or above 1.0)"
        lo, hi = self.logs_to_alarm_range or (np.nan, np.inf)
        hi_s = "no bound" if not np.isfinite(hi) else f"{hi:.0f}"
        return f"{self.logs_to_alarm:.1f} logs ({lo:.0f}..{hi_s})"


def health_index(row: dict[str, Any]) -> float | None:
    """A log's health index: the largest alarm level max(J / eps0, B / b0), 1.0 = alarm;
    max J / eps0 for rows from models without the bias statistic or older results."""
    level = row.get("max_level")
    return level if level is not None else row.get("max_j_ratio")


def prognosis(machine: str, rows: list[dict[str, Any]], k: int = 6) -> Prognosis:
    """Theil-Sen over the last ``k`` judged logs of one machine (rows in time order)."""
    from scipy.stats import kendalltau, theilslopes

    y = [v for r in rows if (v := health_index(r)) is not None and not r["error"]]
    y = np.asarray(y[-k:], dtype=float)
    last = float(y[-1]) if y.size else None
    if y.size < 3:
        return Prognosis(machine, int(y.size), last, None, None, None)
    x = np.arange(y.size, dtype=float)
    slope, intercept, lo, hi = theilslopes(y, x, alpha=0.90)
    if slope <= 0:
        return Prognosis(machine, int(y.size), last, float(slope), None, None)
    p_rise = float(kendalltau(x, y, alternative="greater").pvalue)
    if not p_rise < TREND_P:
        return Prognosis(machine, int(y.size), last, float(slope), None, None, p_rise)
    now = x[-1]
    level = intercept + slope * now

    def until(s: float) -> float:
        return float((1.0 - level) / s) if s > 0 else float("inf")

    rng = (max(until(hi), 0.0), until(lo))
    return Prognosis(machine, int(y.size), last, float(slope), until(slope), rng, p_rise)
