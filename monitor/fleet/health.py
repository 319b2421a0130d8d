"""Health index and prognosis per machine, from logs.parquet rows.

The health index of a log is its largest alarm level (1.0 is the alarm threshold).  It is
what the page shows, but it is a poor quantity to trend: the peak of J over a few minutes
depends on which manoeuvres the log happens to hold, and scatters by a factor of 3-5 on a
healthy machine, while slight wear raises every window a little.  So the trend follows the
log's *typical* level, the median of J / eps0, which moves with wear and barely with the
duty cycle, scaled by the machine's peak-to-typical ratio over the fitted logs (the median
of max / median per log), so that it is in alarm-level units and reaches 1.0 about when a
log's peak would.  Rows written before the median existed are trended on the peak.

The trend is Theil-Sen (median of pairwise slopes, robust to a few odd logs) over the
machine's last ``k`` judged logs, in level per log; the prognosis is the number of logs until
the fitted line reaches 1.0, with the interval from the slope's confidence bounds, or no
upward trend.  A rise counts only when Kendall's tau says it is unlikely to be scatter
(one-sided p < ``TREND_P``): three rising logs of a healthy machine happen by chance one time
in six, and a service visit planned on them is wasted.  So a trend needs at least four
judged logs.

``first_warning`` replays the page over a machine's history, as it would have looked each
morning, to tell whether it warned before the machine's first alarm: by the drift from
commissioning where the machine has one, else by a bounded crossing forecast.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import PurePosixPath
from typing import Any

import numpy as np

#: One-sided p-value of Kendall's tau below which a rise is a trend.
TREND_P = 0.10
#: Drift from commissioning: the median over the last ``DRIFT_LOGS`` judged logs of each
#: log's median J over the commissioning run's (out of sample).  It does not depend on
#: eps0, which one unusual minute of a commissioning run can set high.  On eight simulated
#: fleets (30 machines without wear, 736 five-minute logs) it stayed at or below 1.63;
#: seals wearing 0.003-0.026 a log passed 2 at their 2nd-8th log (docs/benchmarks.md,
#: "Drift from commissioning" and "A first warning from drift").
DRIFT_LOGS = 3
DRIFT_FLAG = 2.0


def drift(rows: list[dict[str, Any]], n: int = DRIFT_LOGS) -> float | None:
    """Median ``p50_j_drift`` of the last ``n`` logs that have one (None: none have)."""
    vals = [r.get("p50_j_drift") for r in rows if not r.get("error")]
    vals = [v for v in vals if v is not None][-n:]
    return float(np.median(vals)) if vals else None


@dataclass(frozen=True)
class Prognosis:
    machine: str
    logs: int  # judged logs in the fit
    last_index: float | None  # the newest judged log's max J / eps0
    slope_per_log: float | None
    logs_to_alarm: float | None  # None: no upward trend (or too few logs)
    logs_to_alarm_range: tuple[float, float] | None  # from the slope's 90 % bounds (inf: none)
    p_value: float | None = None  # Kendall's tau, one-sided, of a rise (None: not tested)
    basis: str = "peak"  # "typical" (median J x peak ratio) or "peak" (the health index)
    level_now: float | None = None  # the trend line at the newest fitted log

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
        return self.logs_text

    @property
    def logs_text(self) -> str:
        """A finite crossing as "12.4 logs (9..52)" (the far end "no bound" when infinite)."""
        assert self.logs_to_alarm is not None
        lo, hi = self.logs_to_alarm_range or (np.nan, np.inf)
        hi_s = "no bound" if not np.isfinite(hi) else f"{hi:.0f}"
        return f"{self.logs_to_alarm:.1f} logs ({lo:.0f}..{hi_s})"


def health_index(row: dict[str, Any]) -> float | None:
    """A log's health index: the largest alarm level max(J / eps0, B / b0, L / l0, H / h0),
    1.0 = alarm; max J / eps0 for rows from models without the bias statistic or older
    results."""
    level = row.get("max_level")
    return level if level is not None else row.get("max_j_ratio")


def trended(rows: list[dict[str, Any]]) -> tuple[np.ndarray, str]:
    """The levels a prognosis fits, one per row, and their basis.

    ``typical``: median J / eps0 of each log times the median over the rows of the log's
    max / median J (every row needs both and a positive median); else ``peak``: the
    health index."""
    peak = [r.get("max_j_ratio") for r in rows]
    mid = [r.get("p50_j_ratio") for r in rows]
    usable = [m is not None and m > 0 and p is not None for m, p in zip(mid, peak, strict=True)]
    if rows and all(usable):
        ratio = float(np.median(np.asarray(peak, float) / np.asarray(mid, float)))
        return np.asarray(mid, float) * ratio, "typical"
    return np.asarray([health_index(r) for r in rows], dtype=float), "peak"


def prognosis(machine: str, rows: list[dict[str, Any]], k: int = 6) -> Prognosis:
    """Theil-Sen over the last ``k`` judged logs of one machine (rows in time order)."""
    from scipy.stats import kendalltau, theilslopes

    judged = [r for r in rows if health_index(r) is not None and not r["error"]][-k:]
    last_index = health_index(judged[-1]) if judged else None
    last = float(last_index) if last_index is not None else None
    if len(judged) < 3:
        return Prognosis(machine, len(judged), last, None, None, None)
    y, basis = trended(judged)
    x = np.arange(y.size, dtype=float)
    slope, intercept, lo, hi = theilslopes(y, x, alpha=0.90)
    level = float(intercept + slope * x[-1])
    if slope <= 0:
        return Prognosis(machine, y.size, last, float(slope), None, None, None, basis, level)
    p_rise = float(kendalltau(x, y, alternative="greater").pvalue)
    if not p_rise < TREND_P:
        return Prognosis(machine, y.size, last, float(slope), None, None, p_rise, basis, level)

    def until(s: float) -> float:
        return float((1.0 - level) / s) if s > 0 else float("inf")

    rng = (max(until(hi), 0.0), until(lo))
    return Prognosis(machine, y.size, last, float(slope), until(slope), rng, p_rise, basis, level)


def replay(machine: str, rows: list[dict[str, Any]], k: int = 6) -> list[Prognosis]:
    """The prognosis as of each row (rows in time order): entry i is made from rows[:i+1]."""
    return [prognosis(machine, rows[: i + 1], k) for i in range(len(rows))]


def log_day(row: dict[str, Any]) -> int | None:
    """The day number in the log's file name (``day03-1.log`` -> 3), None without one.

    ``monitor simulate-fleet`` names logs so; uploaders' own names may carry no day."""
    m = re.match(r"day(\d+)", PurePosixPath(row["log"]).name)
    return int(m.group(1)) if m else None


@dataclass(frozen=True)
class FirstWarning:
    """Whether a machine's page forecast a crossing before its first alarm.

    Log numbers are 1-based positions in the machine's rows (time order), as on the plots."""

    machine: str
    warning_log: int | None  # the first log that warned, no alarm yet
    warning_name: str | None  # that log's file stem, e.g. "day03-1"
    forecast: Prognosis | None  # the prognosis made at that log (forecast warnings)
    alarm_log: int | None  # the first log with ``alarm``
    alarm_name: str | None
    lead_logs: int | None  # alarm_log - warning_log (None unless both)
    lead_days: int | None  # the same in days, when both file names carry a day
    drift: float | None = None  # the drift from commissioning that warned (drift warnings)

    @property
    def text(self) -> str:
        if self.warning_log is None:
            if self.alarm_log is None:
                return "-"
            return f"no warning before the alarm at log {self.alarm_log} ({self.alarm_name})"
        if self.drift is not None:
            due = f"drift {self.drift:.1f} x"
        else:
            f = self.forecast
            assert f is not None and f.logs_to_alarm is not None  # set with warning_log
            due = "crossing due now" if f.logs_to_alarm <= 0 else f"crossing in {f.logs_text}"
        head = f"log {self.warning_log} ({self.warning_name}): {due}"
        if self.alarm_log is None:
            return f"{head}; no alarm yet"
        days = "" if self.lead_days is None else f", {self.lead_days} d"
        return (
            f"{head}; alarm at log {self.alarm_log} ({self.alarm_name}), "
            f"{self.lead_logs} logs{days} later"
        )


def _drift_warning(rows: list[dict[str, Any]]) -> tuple[int | None, float | None]:
    """The first row (0-based) at which the drift reached ``DRIFT_FLAG``, and that drift."""
    for i in range(len(rows)):
        d = drift(rows[: i + 1])
        if d is not None and d >= DRIFT_FLAG:
            return i, d
    return None, None


def _forecast_warning(
    machine: str, rows: list[dict[str, Any]], k: int
) -> tuple[int | None, Prognosis | None]:
    """The first row (0-based) whose prognosis gave a bounded crossing, and that prognosis
    (as ``replay``, but stopping there)."""
    for i in range(len(rows)):
        p = prognosis(machine, rows[: i + 1], k)
        bounded = p.logs_to_alarm_range is not None and np.isfinite(p.logs_to_alarm_range[1])
        if p.logs_to_alarm is not None and bounded:
            return i, p
    return None, None


def first_warning(machine: str, rows: list[dict[str, Any]], k: int = 6) -> FirstWarning:
    """The first warning and first alarm of one machine (rows in time order).

    A warning is a log at which neither it nor any earlier log had alarmed (a warning with
    or after the alarm tells the service team nothing the alarm did not) and:

    - on a machine with a drift from commissioning (any row has ``p50_j_drift``): the drift
      reached ``DRIFT_FLAG``.  Not the forecast: in the simulator a seal's wear shows as a
      step (a leak of severity 0.01 already equalises the trapped end-stop pressures), so
      the level sits flat below 1.0 for days with nothing to trend; on eight simulated
      fleets the forecast warned on 13 of 30 machines without wear, the drift on none;
    - else: a bounded crossing forecast, ``logs_to_alarm`` set ("due now" included) and the
      far end of its interval finite (even the slope's lower 90 % bound rises); one without
      a far end is the scatter of a healthy machine more often than wear."""
    alarm_i = next((i for i, r in enumerate(rows) if r["alarm"]), None)  # None: never
    before = rows if alarm_i is None else rows[:alarm_i]
    forecast = warn_drift = None
    if any(r.get("p50_j_drift") is not None for r in rows):
        warn_i, warn_drift = _drift_warning(before)
    else:
        warn_i, forecast = _forecast_warning(machine, before, k)

    def name(i: int | None) -> str | None:
        return None if i is None else PurePosixPath(rows[i]["log"]).stem

    lead_logs = lead_days = None
    if warn_i is not None and alarm_i is not None:
        lead_logs = alarm_i - warn_i
        d0, d1 = log_day(rows[warn_i]), log_day(rows[alarm_i])
        lead_days = None if d0 is None or d1 is None else d1 - d0
    return FirstWarning(
        machine,
        None if warn_i is None else warn_i + 1,
        name(warn_i),
        forecast,
        None if alarm_i is None else alarm_i + 1,
        name(alarm_i),
        lead_logs,
        lead_days,
        warn_drift,
    )
