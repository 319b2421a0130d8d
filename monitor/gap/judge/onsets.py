"""How late the recording moves at the spool's openings from centre and at its closings: the
signature that tells a valve deadband from a delay every reading shares.

A deadband (an overlapped spool) passes no flow until the spool has travelled past the
overlap: a move out of a centred spool starts late, by the time the command takes to cross
the overlap, and a spool coming back to centre cuts the flow off *early*, by the same time
(and a command smaller than the overlap opens nothing).  A delay every reading shares (the
recording's clock against its commands, the transducers' electronics) shifts every sample
alike: the openings, the closings, the reversals and the pressures' responses to a closing.
So the recording's delay against the calibrated simulator is fitted twice, on the samples
just after each opening out of centre and on those around each return to centre; the
difference (openings minus closings) is about twice the overlap's crossing time under a
deadband and zero under a shared delay.

Each event's window is a cost curve over the delay grid (least squares of the readings,
each normalised by its spread, an offset per window and signal removed: a leak or a load
carries no timing); summed per kind, its minimum is that kind's delay, and resampling the
events gives the share of resamples in which the openings are later by ``APART_MS``.
No simulation.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from monitor.gap.data.prepare import Prepared
from monitor.gap.data.segments import Segment
from monitor.gap.fit.score import compared
from monitor.signals import SAMPLE_PERIOD_S

#: The spool counts as centred below this command (% stroke).
CENTRE_PCT = 2.0
#: An opening starts from a spool centred this long (s).
QUIET_S = 0.2
#: A closing is a command falling through this (% stroke) that reaches centre within
#: ``WINDOW_S``: where a ramp back to centre passes the overlaps the catalogue spans.
CLOSING_PCT = 20.0
#: Each event's window: from two samples before it to this after it (s).
WINDOW_S = 0.3
#: A window shorter than this (s) is not used.
MIN_WINDOW_S = 0.1
#: Delays tried (ms): a closing under a deadband reads early.
GRID_MS = np.arange(-60.0, 81.0, 1.0)
#: Openings later than closings by this (ms, one sample) is a deadband's signature.
APART_MS = 10.0
#: Fewer events of either kind than this: the timing says nothing.
MIN_EVENTS = 5
RESAMPLES = 400


@dataclass(frozen=True)
class Onsets:
    """The recording's delay (ms) against a simulation at the openings and the closings."""

    open_ms: float
    close_ms: float
    n_open: int
    n_close: int
    #: Share of resamples of the events with the openings ``APART_MS`` or more later.
    apart_share: float

    @property
    def asymmetry_ms(self) -> float:
        return self.open_ms - self.close_ms

    def as_dict(self) -> dict:
        return {
            "opening_ms": round(self.open_ms, 1),
            "closing_ms": round(self.close_ms, 1),
            "asymmetry_ms": round(self.asymmetry_ms, 1),
            "openings": self.n_open,
            "closings": self.n_close,
            "apart_share": round(self.apart_share, 3),
        }


def events(
    cmd: np.ndarray, segments: Sequence[Segment]
) -> tuple[list[tuple[int, int]], list[tuple[int, int]]]:
    """Windows (rows ``lo .. hi``) of the openings out of a centred spool and of the returns
    to centre, within the segments' scored rows.  A segment ends soon after the spool came
    back to centre, so a closing's window ends where its segment does (less the longest
    early shift tried), at least ``MIN_WINDOW_S`` after the event."""
    a = np.abs(cmd)
    quiet, win, least = _samples(QUIET_S), _samples(WINDOW_S), _samples(MIN_WINDOW_S)
    margin = int(np.ceil(-GRID_MS[0] * 1e-3 / SAMPLE_PERIOD_S)) + 1
    opens: list[tuple[int, int]] = []
    closes: list[tuple[int, int]] = []
    for seg in segments:
        end = seg.stop - margin
        for i in range(seg.score_from + max(quiet, 2), end - least):
            hi = min(i + win, end)
            if a[i] > CENTRE_PCT >= a[i - 1] and np.all(a[i - quiet : i] <= CENTRE_PCT):
                opens.append((i - 2, hi))
            elif a[i] < CLOSING_PCT <= a[i - 1] and np.any(a[i : i + win] <= CENTRE_PCT):
                closes.append((i - 2, hi))
    return opens, closes


def _samples(seconds: float) -> int:
    return int(round(seconds / SAMPLE_PERIOD_S))


def _curves(
    prep: Prepared,
    meas: dict[str, np.ndarray],
    pred: dict[str, np.ndarray],
    windows: list[tuple[int, int]],
    signals: Sequence[str] | None = None,
) -> np.ndarray:
    """Per event, the cost of each delay in ``GRID_MS`` (events x grid), summed over
    ``signals`` (default: every compared signal)."""
    shift = GRID_MS * 1e-3 / SAMPLE_PERIOD_S
    out = np.zeros((len(windows), len(GRID_MS)))
    for name in compared(prep) if signals is None else signals:
        y_all, x_all = meas[name], pred[name]
        scale = max(prep.scale.get(name, 1.0), 1e-9)
        for k, (lo_row, hi_row) in enumerate(windows):
            t = np.arange(lo_row, hi_row)
            y = y_all[t]
            pos = t[None, :] - shift[:, None]
            lo = np.clip(np.floor(pos).astype(int), 0, len(x_all) - 2)
            frac = pos - lo
            x = x_all[lo] * (1.0 - frac) + x_all[lo + 1] * frac
            res = (y[None, :] - x) / scale
            ok = np.all(np.isfinite(res), axis=0)
            if ok.sum() < 5:
                continue
            res = res[:, ok]
            res = res - res.mean(axis=1, keepdims=True)
            out[k] += np.sum(res**2, axis=1)
    return out


def measure(
    prep: Prepared,
    segments: Sequence[Segment],
    pred: dict[str, np.ndarray],
    meas: dict[str, np.ndarray] | None = None,
) -> Onsets | None:
    """How late ``meas`` (default: the recording) is against ``pred`` at the openings and
    at the closings; None with fewer than ``MIN_EVENTS`` of either."""
    meas = prep.meas if meas is None else meas
    opens, closes = events(prep.cmd["SpoolCmd"], segments)
    if len(opens) < MIN_EVENTS or len(closes) < MIN_EVENTS:
        return None
    co, cc = _curves(prep, meas, pred, opens), _curves(prep, meas, pred, closes)
    open_ms, close_ms, share = _apart(co, cc)
    return Onsets(open_ms, close_ms, len(opens), len(closes), share)


def _apart(
    later: np.ndarray, earlier: np.ndarray, same_events: bool = False
) -> tuple[float, float, float]:
    """The delays two sets of event curves minimise, and the share of resamples of the
    events (one resample for both when they are the same events) in which the first is
    ``APART_MS`` or more later."""
    rng = np.random.default_rng(0)
    n, m = len(later), len(earlier)
    bl = rng.integers(0, n, (RESAMPLES, n))
    be = bl if same_events else rng.integers(0, m, (RESAMPLES, m))
    d_l = GRID_MS[np.argmin(later[bl].sum(axis=1), axis=1)]
    d_e = GRID_MS[np.argmin(earlier[be].sum(axis=1), axis=1)]
    return (
        float(GRID_MS[np.argmin(later.sum(axis=0))]),
        float(GRID_MS[np.argmin(earlier.sum(axis=0))]),
        float(np.mean(d_l - d_e >= APART_MS)),
    )


#: The cylinder chambers' readings, and the pump's (pressure and flow).
CHAMBERS = ("PA", "PB")
PUMP = ("PP", "QP")


def chambers_apart(
    prep: Prepared, segments: Sequence[Segment], pred: dict[str, np.ndarray]
) -> dict | None:
    """At the returns to centre, how much later the pump's readings (PP, QP) are than the
    chambers' (PA, PB) against ``pred``.  A lag of the readings delays every reading it
    acts on by the same at every event; a compliance of the cylinder lines does not: as the
    spool closes, the chambers' pressures settle at once while the pump, still feeding the
    soft lines, keeps its pressure and flow up (the third plant's hoses: the pump's
    readings 21-80 ms later than the chambers' at the closings, its lagged sensors within
    3 ms).  None with fewer than ``MIN_EVENTS`` closings."""
    _, closes = events(prep.cmd["SpoolCmd"], segments)
    if len(closes) < MIN_EVENTS:
        return None
    pump = _curves(prep, prep.meas, pred, closes, PUMP)
    chambers = _curves(prep, prep.meas, pred, closes, CHAMBERS)
    pump_ms, chambers_ms, share = _apart(pump, chambers, same_events=True)
    return {
        "pump_closing_ms": round(pump_ms, 1),
        "chambers_closing_ms": round(chambers_ms, 1),
        "closings": len(closes),
        "apart_share": round(share, 3),
    }
