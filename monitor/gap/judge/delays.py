"""How late each reading is against the calibrated simulator: the signature that tells a
sensor's dynamics from the machine's.

A sensor lag delays the reading, not the machine: the pressures read late while the rod
(RodPos, measured by its own sensor) and any signal read by a prompt sensor move on time.
A slow spool or pump, or a soft line, makes the machine itself late, and every signal it
drives shares the delay, the rod included.  Per compared signal, the delay is the lag
(within +-``MAX_LAG_S``) at which the measured signal's sample-to-sample change correlates
best with the simulated one's over the held-out segments, refined between samples by a
parabola through the peak.  Changes, not levels: a level error (a leak, a load) carries no
timing.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from monitor.gap.data.prepare import Prepared
from monitor.gap.data.segments import Segment
from monitor.gap.fit.score import compared
from monitor.gap.fit.sensorterms import SensorTerm
from monitor.signals import SAMPLE_PERIOD_S

#: Lags searched either way (s): longer than the catalogue's sensor lags and slow spools.
MAX_LAG_S = 0.12
#: Delays a fitted re-timing tries (ms).
GRID_MS = np.arange(0.0, 1e3 * MAX_LAG_S / 2 + 1.0, 1.0)
#: A signal's peak correlation below this says nothing about its timing.
MIN_CORRELATION = 0.3
#: A delay the rod does not share by this much is the readings' (ms: one sample).
APART_MS = 10.0
PRESSURES = ("PP", "PA", "PB")
#: The readings a sensor's dynamics can delay (RodPos is read by its own sensor and is not
#: lagged: ``predict.sense``).
READINGS = ("PP", "PA", "PB", "QP")
#: A delay every reading shares, the rod included, up to this is the recording's
#: acquisition (its clock against the commands, transducer electronics, the bus), not a
#: fault of the machine: the third plant's healthy machines read 8-20 ms behind the
#: calibrated simulator on every signal; its slow spools (3-8 Hz) 36-50 ms.
SHARED_MAX_MS = 25.0
#: Below this a shared delay is within one sample's jitter: nothing to note.
SHARED_MIN_MS = 5.0
#: Readings a compliance of the cylinder lines (air, hoses) makes late together: when both
#: are late, their delay alone does not tell a sensor from the oil.
CHAMBERS = frozenset({"PA", "PB"})


def _xcorr(meas: np.ndarray, sim: np.ndarray, segments: Sequence[Segment], k: int) -> np.ndarray:
    """Correlation of measured against simulated changes at lags -k..k samples (positive:
    the measurement later), pooled over the segments."""
    num, den_m, den_s = np.zeros(2 * k + 1), np.zeros(2 * k + 1), np.zeros(2 * k + 1)
    for seg in segments:
        dm = np.diff(meas[seg.scored])
        ds = np.diff(sim[seg.scored])
        n = len(dm)
        if n <= 2 * k + 1:
            continue
        for j, lag in enumerate(range(-k, k + 1)):
            a = dm[k + lag : n - k + lag]
            b = ds[k : n - k]
            ok = np.isfinite(a) & np.isfinite(b)
            num[j] += float(a[ok] @ b[ok])
            den_m[j] += float(a[ok] @ a[ok])
            den_s[j] += float(b[ok] @ b[ok])
    with np.errstate(invalid="ignore", divide="ignore"):
        return num / np.sqrt(den_m * den_s)


def delays_ms(
    prep: Prepared, segments: Sequence[Segment], pred: dict[str, np.ndarray]
) -> dict[str, float | None]:
    """Per compared signal: how many ms the reading lags the simulator (None: no timing in
    it, its changes do not follow the simulator's)."""
    k = int(round(MAX_LAG_S / SAMPLE_PERIOD_S))
    out: dict[str, float | None] = {}
    for name in compared(prep):
        r = _xcorr(prep.meas[name], pred[name], segments, k)
        if not np.any(np.isfinite(r)) or np.nanmax(r) < MIN_CORRELATION:
            out[name] = None
            continue
        j = int(np.nanargmax(r))
        frac = 0.0
        if 0 < j < 2 * k and np.all(np.isfinite(r[j - 1 : j + 2])):
            y0, y1, y2 = r[j - 1], r[j], r[j + 1]
            curv = y0 - 2 * y1 + y2
            frac = 0.5 * (y0 - y2) / curv if curv < 0 else 0.0
        out[name] = round(float(1e3 * (j - k + frac) * SAMPLE_PERIOD_S), 1)
    return out


def shared(delays: dict[str, float | None], signals: Sequence[str]) -> float | None:
    """The median delay of ``signals`` (those with a timing), None without any."""
    vals = [d for s in signals if (d := delays.get(s)) is not None]
    return float(np.median(vals)) if vals else None


def machine_late(delays: dict[str, float | None]) -> bool | None:
    """Whether the rod moves as late as the pressures read, and they read late (the machine
    itself is late: a slow spool or pump, not a sensor); None without a rod or pressure
    timing."""
    p, rod = shared(delays, PRESSURES), delays.get("RodVel")
    if p is None or rod is None:
        return None
    return p >= APART_MS and p - rod < APART_MS


@dataclass(frozen=True)
class Split:
    """Which readings are later than the rest (a sensor's lag), and the delay the rest share.

    The reference is the rod (RodPos, not lagged by a pressure or flow sensor) when it has a
    timing, else the median of the readings: a reading later than it by ``APART_MS`` is
    ``late``; what the others (the rod included) share is ``shared_ms``."""

    reference: str  # "rod" or "readings"
    reference_ms: float
    late: tuple[str, ...]
    shared_ms: float | None

    @property
    def some_late(self) -> bool:
        """Some readings are late and some are not: a sensor's lag the others do not share
        (unless both cylinder chambers are among them, which a compliance of the lines
        delays together: the third plant's soft hose read PA, PB and QP 13-17 ms later
        than the rod, its air PA and PB 18-21 ms)."""
        late = set(self.late)
        return bool(late) and len(late) < len(READINGS) and not late >= CHAMBERS

    @property
    def shared(self) -> bool:
        """Every reading shares one delay (none stands out) of ``SHARED_MIN_MS`` to
        ``SHARED_MAX_MS``: the recording's timing, not the machine's physics."""
        return (
            not self.late
            and self.shared_ms is not None
            and SHARED_MIN_MS <= self.shared_ms <= SHARED_MAX_MS
        )

    def as_dict(self) -> dict:
        return {
            "reference": self.reference,
            "reference_ms": round(self.reference_ms, 1),
            "late_signals": list(self.late),
            "shared_ms": None if self.shared_ms is None else round(self.shared_ms, 1),
        }


def fitted_ms(
    prep: Prepared, segments: Sequence[Segment], pred: dict[str, np.ndarray], signals: Sequence[str]
) -> dict[str, float]:
    """Per signal: the delay (ms, on a 1 ms grid to 60 ms) of the simulated reading
    that matches the recording best over ``segments`` (least squares): a delay fitted, where
    ``delays_ms`` locates a correlation peak (biased towards whole samples)."""
    rows = np.concatenate([np.arange(s.score_from, s.stop) for s in segments])
    out = {}
    for name in signals:
        y = prep.meas[name][rows]
        costs = []
        for ms in GRID_MS:
            x = SensorTerm("sensor_delay", name, float(ms)).apply(prep, segments, pred)[name]
            r = x[rows] - y
            costs.append(float(np.nanmean(r**2)) if np.any(np.isfinite(r)) else np.inf)
        out[name] = float(GRID_MS[int(np.argmin(costs))])
    return out


def split(delays: dict[str, float | None]) -> Split | None:
    """The readings later than the rod (or than the readings' median, without a rod), and
    the delay the others share; None when fewer than two readings have a timing."""
    timed = {s: d for s in READINGS if (d := delays.get(s)) is not None}
    if len(timed) < 2:
        return None
    rod = delays.get("RodVel")
    median = float(np.median(list(timed.values())))
    ref, by = (rod, "rod") if rod is not None else (median, "readings")
    late = tuple(s for s, d in timed.items() if d - ref >= APART_MS)
    rest = [d for s, d in timed.items() if s not in late] + ([rod] if rod is not None else [])
    return Split(by, float(ref), late, float(np.median(rest)) if rest else None)
