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

import numpy as np

from monitor.gap.data.prepare import Prepared
from monitor.gap.data.segments import Segment
from monitor.gap.fit.score import compared
from monitor.signals import SAMPLE_PERIOD_S

#: Lags searched either way (s): longer than the catalogue's sensor lags and slow spools.
MAX_LAG_S = 0.12
#: A signal's peak correlation below this says nothing about its timing.
MIN_CORRELATION = 0.3
#: A delay the rod does not share by this much is the readings' (ms: one sample).
APART_MS = 10.0
PRESSURES = ("PP", "PA", "PB")


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
