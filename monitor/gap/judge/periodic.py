"""The periodic load's frequency: a line of the calibration residual's spectrum, so that a
periodic term's amplitude and phase are all ``suggest`` fits (two linear coefficients)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.ndimage import uniform_filter1d

from monitor.gap.data.prepare import Prepared
from monitor.gap.data.segments import Segment
from monitor.gap.fit import score as S

Pred = dict[str, np.ndarray]

#: The periodic load's frequency is searched in this band (Hz).
PERIODIC_BAND_HZ = (0.1, 20.0)
#: A line's prominence is its power over the spectrum's local (log) mean within this (Hz):
#: without RodPos the residual's power is largest below 0.5 Hz (the rod integrated from
#: the flow drifts), and the strongest bin there is no line.
PROMINENCE_WINDOW_HZ = 0.2
#: Candidate lines tried for the periodic load: the strongest and the most prominent.
N_LINES = 1
#: Lines closer than this (Hz) are one line.
LINE_SEPARATION_HZ = 0.05


def periodic_frequencies_hz(prep: Prepared, segments: Sequence[Segment], pred: Pred) -> list[float]:
    """Candidate lines of the residual's spectrum in ``PERIODIC_BAND_HZ`` (power summed over
    the compared signals; the residual outside the segments set to zero, zero-padded
    eightfold and each peak interpolated: a line's frequency to a small share of
    1/duration): the ``N_LINES`` strongest and the ``N_LINES`` most prominent (power over
    the local mean of the log spectrum), whichever the plant fit then prefers."""
    r = S.normalised(prep, pred)
    dt = float(prep.t[1] - prep.t[0])
    n = 8 * len(prep)
    power = np.zeros(n // 2 + 1)
    for v in r.values():
        x = np.zeros(len(prep))
        for seg in segments:
            # Each segment's quadratic trend removed: a residual drifting over seconds (a rod
            # integrated from the flow, a slow load) would otherwise leak through the
            # segments' on-off pattern into lines at multiples of its repetition rate.
            y = np.nan_to_num(v[seg.scored])
            rows = np.arange(y.size)
            if y.size > 2:
                y = y - np.polyval(np.polyfit(rows, y, 2), rows)
            x[seg.scored] = y
        power += np.abs(np.fft.rfft(x, n)) ** 2
    df = 1.0 / (n * dt)
    log_p = np.log(power + 1e-300)
    width = max(int(PROMINENCE_WINDOW_HZ / df), 3)
    prominence = log_p - uniform_filter1d(log_p, width, mode="nearest")
    lo, hi = (int(round(f / df)) for f in PERIODIC_BAND_HZ)
    out: list[float] = []
    for score in (log_p, prominence):
        s = score[lo:hi].copy()
        for _ in range(N_LINES):
            i = lo + int(np.argmax(s))
            a, b, c = log_p[i - 1 : i + 2]
            shift = 0.5 * (a - c) / (a - 2 * b + c) if (a - 2 * b + c) < 0 else 0.0
            f = (i + shift) * df
            if all(abs(f - g) > LINE_SEPARATION_HZ for g in out):
                out.append(float(f))
            k = int(LINE_SEPARATION_HZ / df)
            s[max(i - lo - k, 0) : i - lo + k + 1] = -np.inf
    return out
