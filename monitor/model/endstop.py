"""Where the boom cylinder's rod may be, from pump flow alone: is a hold on an end stop?

A hold on an end stop is not the valve's business: the stop carries the load, the chamber
pressures settle where the lowering or lifting left them, and the healthy model, which
learnt holds mid-stroke, predicts them badly.  The hold statistic H must leave such holds
out, or a healthy machine lowered into its stop raises H (docs/benchmarks.md, "The hold
statistic H").  RodPos is optional on the bus, so the stop is told from SpoolCmd and QP:

- With the lever out (|SpoolCmd| > ``HOLD_PCT``), the pump's flow fills one chamber: the rod
  travels ``QP * dt / volume`` of its stroke, up with a positive command (``volume_up_l``, the
  cap side's swept volume), down with a negative one (``volume_down_l``, the rod side's).
- A stall (lever out, QP below ``q_stall_lpm`` for ``n_stall`` samples) is the rod on the end
  stop in the lever's direction.

The rod's place is kept as an interval ``[lo, hi]`` of stroke fractions: unknown at the
start (0..1) and after a gap (a NaN command or flow), a point at a stall, shifted by each
sample's travel and cut at the ends, so a long travel one way anchors it too.  A sample is
*possibly on a stop* while the interval comes within ``margin`` of either end.  The volumes
come from healthy data: between two stalls the up- and down-travel add up to 0 (back to the
same stop) or to +-1 stroke (to the other), one linear equation per pair of stalls, solved
for ``1 / volume_up_l`` and ``1 / volume_down_l`` by least squares.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from monitor.errors import ConfigError, InputFileError
from monitor.jit import jit
from monitor.model.bias import HOLD_PCT
from monitor.model.fields import fields_from_dict, fields_to_dict
from monitor.model.filecheck import MAX_WINDOW_N, check_number
from monitor.signals import SAMPLE_PERIOD_S

#: Pump flow below which a lever held out means the rod stands on a stop (L/min).
Q_STALL_LPM = 1.0
#: Samples of such flow before it counts as a stall (0.2 s: a reversal passes zero faster).
N_STALL = 20
#: How near an end (stroke fraction) the interval must come to be "possibly on a stop".  The
#: travel between two stalls is off by at most 0.036 stroke on simulated healthy runs.
MARGIN = 0.05
#: Pairs of stalls at opposite ends the fit needs each way: each one is a whole stroke
#: measured (to about 1 %), so one would do; two guard against a stall mid-stroke.
MIN_STROKES = 2


@dataclass(frozen=True)
class StrokeModel:
    """The cylinder's swept volumes (litres) and how the end-stop estimate uses them."""

    volume_up_l: float  # pump flow that lifts the rod by one stroke (cap side)
    volume_down_l: float  # pump flow that lowers it by one stroke (rod side)
    margin: float = MARGIN  # stroke fraction
    q_stall_lpm: float = Q_STALL_LPM
    n_stall: int = N_STALL  # samples

    def __post_init__(self) -> None:
        vols = (self.volume_up_l, self.volume_down_l)
        if not all(np.isfinite(v) and v > 0 for v in vols):
            raise ConfigError(f"stroke volumes must be positive litres, got {vols}")
        if not 0 <= self.margin < 0.5 or not self.q_stall_lpm > 0 or self.n_stall < 1:
            raise ConfigError(
                f"end-stop margin {self.margin}, stall flow {self.q_stall_lpm} L/min and "
                f"stall samples {self.n_stall} must satisfy 0 <= margin < 0.5, flow > 0, n >= 1"
            )

    def to_dict(self) -> dict[str, object]:
        return fields_to_dict(self)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> StrokeModel:
        return fields_from_dict(cls, d)


# State vector of the step kernel: the interval and the stall count.
_LO, _HI, _RUN = 0, 1, 2
_STATE = 3


def new_state() -> np.ndarray:
    """The kernel's state before the first sample: rod anywhere, no stall."""
    return np.array([0.0, 1.0, 0.0])


@jit(aot=True)
def _step(
    state, spool, qp, inv_up, inv_down, margin, q_stall, n_stall, per_min, hold_pct
):  # pragma: no cover - numba
    """One sample; returns 1 when the rod may be within ``margin`` of an end, else 0.
    ``inv_up`` / ``inv_down``: strokes per litre; ``per_min``: minutes per sample."""
    if np.isnan(spool) or np.isnan(qp):
        state[_LO] = 0.0  # a gap: the rod may have gone anywhere
        state[_HI] = 1.0
        state[_RUN] = 0.0
    elif abs(spool) > hold_pct:
        state[_RUN] = state[_RUN] + 1.0 if qp < q_stall else 0.0
        if state[_RUN] >= n_stall:
            end = 1.0 if spool > 0 else 0.0
            state[_LO] = end
            state[_HI] = end
        elif spool > 0:
            d = max(qp, 0.0) * per_min * inv_up
            state[_LO] = min(1.0, state[_LO] + d)
            state[_HI] = min(1.0, state[_HI] + d)
        else:
            d = max(qp, 0.0) * per_min * inv_down
            state[_LO] = max(0.0, state[_LO] - d)
            state[_HI] = max(0.0, state[_HI] - d)
    else:
        state[_RUN] = 0.0
    return 1 if state[_LO] < margin or state[_HI] > 1.0 - margin else 0


@jit(aot=True)
def _series(
    spool, qp, state, inv_up, inv_down, margin, q_stall, n_stall, per_min, hold_pct
):  # pragma: no cover - numba
    out = np.empty(spool.shape[0], dtype=np.int64)
    for i in range(spool.shape[0]):
        out[i] = _step(
            state, spool[i], qp[i], inv_up, inv_down, margin, q_stall, n_stall, per_min, hold_pct
        )
    return out


def _args(stroke: StrokeModel) -> tuple[float, ...]:
    per_min = SAMPLE_PERIOD_S / 60.0
    return (
        1.0 / stroke.volume_up_l,
        1.0 / stroke.volume_down_l,
        stroke.margin,
        stroke.q_stall_lpm,
        float(stroke.n_stall),
        per_min,
        HOLD_PCT,
    )


def near_stop_series(spool_pct: np.ndarray, qp_lpm: np.ndarray, stroke: StrokeModel) -> np.ndarray:
    """Per sample: 1 where the rod may be on (within the margin of) an end stop, else 0."""
    s = np.ascontiguousarray(spool_pct, dtype=np.float64)
    q = np.ascontiguousarray(qp_lpm, dtype=np.float64)
    if s.shape != q.shape or s.ndim != 1:
        raise InputFileError(f"SpoolCmd {s.shape} and QP {q.shape} must be one series each")
    return _series(s, q, new_state(), *_args(stroke))


class StopTracker:
    """The end-stop estimate one tick at a time (the live ticker's; same kernel)."""

    def __init__(self, stroke: StrokeModel) -> None:
        self._state = new_state()
        self._args = _args(stroke)

    def push(self, spool_pct: float, qp_lpm: float) -> int:
        """One sample; 1 when the rod may be on an end stop."""
        return int(_step(self._state, spool_pct, qp_lpm, *self._args))


@jit
def _stall_ends(spool, qp, state, q_stall, n_stall, hold_pct):  # pragma: no cover - numba
    """Per sample: +1 / -1 while stalled at the top / bottom stop, 0 otherwise: the
    tracker's own step, without travel, read where its interval collapses."""
    out = np.zeros(spool.shape[0], dtype=np.int64)
    for i in range(spool.shape[0]):
        _step(state, spool[i], qp[i], 0.0, 0.0, 0.0, q_stall, n_stall, 1.0, hold_pct)
        if state[_RUN] >= n_stall:
            out[i] = 1 if state[_LO] > 0.5 else -1
    return out


def stroke_equations(spool_pct: np.ndarray, qp_lpm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One equation per pair of consecutive stalls of one recording: rows (litres up, -litres
    down) and right-hand sides (+1 bottom to top, -1 top to bottom, 0 back to the same stop).
    A gap (NaN command or flow) between two stalls drops that pair."""
    s = np.asarray(spool_pct, dtype=np.float64)
    q = np.asarray(qp_lpm, dtype=np.float64)
    ends = _stall_ends(
        np.ascontiguousarray(s),
        np.ascontiguousarray(q),
        new_state(),
        Q_STALL_LPM,
        float(N_STALL),
        HOLD_PCT,
    )
    with np.errstate(invalid="ignore"):
        litres = np.where(np.isfinite(q), np.maximum(q, 0.0), 0.0) * SAMPLE_PERIOD_S / 60.0
        up = np.where((s > HOLD_PCT) & (ends == 0), litres, 0.0)
        down = np.where((s < -HOLD_PCT) & (ends == 0), litres, 0.0)
    bad = ~(np.isfinite(s) & np.isfinite(q))
    c_up, c_down, c_bad = np.cumsum(up), np.cumsum(down), np.cumsum(bad)
    stalled = np.flatnonzero(ends != 0)
    if stalled.size == 0:
        return np.zeros((0, 2)), np.zeros(0)
    # Each stall is a run of stalled samples; the travel between two is counted from the
    # last sample of one to the first of the next.
    breaks = np.flatnonzero((np.diff(stalled) > 1) | (np.diff(ends[stalled]) != 0))
    first = stalled[np.r_[0, breaks + 1]]
    last = stalled[np.r_[breaks, stalled.size - 1]]
    a, b = last[:-1], first[1:]
    ok = c_bad[b] == c_bad[a]
    rows = np.column_stack([c_up[b] - c_up[a], -(c_down[b] - c_down[a])])[ok]
    rhs = ((ends[b] - ends[a]) / 2.0)[ok]
    return rows, rhs


def fit_stroke(spool: list[np.ndarray], qp: list[np.ndarray]) -> StrokeModel:
    """The swept volumes from healthy recordings' SpoolCmd (%) and QP (L/min), by least
    squares over every pair of consecutive stalls.  ``InputFileError`` when the data runs the
    rod from stop to stop fewer than ``MIN_STROKES`` times each way."""
    eqs = [stroke_equations(s, q) for s, q in zip(spool, qp, strict=True)]
    rows = np.concatenate([r for r, _ in eqs]) if eqs else np.zeros((0, 2))
    rhs = np.concatenate([h for _, h in eqs]) if eqs else np.zeros(0)
    ups, downs = int(np.sum(rhs > 0)), int(np.sum(rhs < 0))
    if min(ups, downs) < MIN_STROKES:
        raise InputFileError(
            f"the normal data runs the rod from end stop to end stop {ups} times up "
            f"and {downs} times down; the end-stop estimate needs {MIN_STROKES} each way "
            "(a stall: the lever out and QP below "
            f"{Q_STALL_LPM:g} L/min for {N_STALL * SAMPLE_PERIOD_S:g} s)"
        )
    (inv_up, inv_down), *_ = np.linalg.lstsq(rows, rhs, rcond=None)
    if not (inv_up > 0 and inv_down > 0):
        raise InputFileError(
            f"the stalls in the normal data give no positive swept volumes (fitted "
            f"{inv_up:.4g} and {inv_down:.4g} strokes per litre): is QP the pump's outlet flow?"
        )
    return StrokeModel(1.0 / float(inv_up), 1.0 / float(inv_down))


def check_stroke_section(stroke: Any, where: str) -> None:
    """A model file's end-stop estimate (header section ``where``, as ``hold.stroke``):
    volumes, margin and stall rule; ``ValueError`` naming the key."""
    if not isinstance(stroke, dict):
        raise ValueError(f"header {where} must be an object")
    for key, low, strict in (
        ("volume_up_l", 0.0, True),
        ("volume_down_l", 0.0, True),
        ("margin", 0.0, False),
        ("q_stall_lpm", 0.0, True),
    ):
        try:
            check_number(stroke, key, low, strict)
        except ValueError as exc:
            raise ValueError(str(exc).replace("header ", f"header {where}.", 1)) from None
    if stroke["margin"] >= 0.5:
        raise ValueError(f"header {where}.margin must be < 0.5, got {stroke['margin']:g}")
    v = stroke.get("n_stall")
    if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= MAX_WINDOW_N:
        raise ValueError(f"header {where}.n_stall must be a whole number 1..{MAX_WINDOW_N}")


def settling_on_stop(spool_pct: np.ndarray, qp_lpm: np.ndarray) -> np.ndarray:
    """Per sample: True from a stall (the rod on an end stop, see the module docstring) until
    the lever next moves the rod (out beyond ``HOLD_PCT`` with QP at or above
    ``Q_STALL_LPM``): the stop carries the load and the chamber pressures settle across the
    lands from where the stall left them, by a path that depends on the payload and the pose,
    which one session of commissioning cannot show.  No stroke volumes needed.  The same rule
    as :class:`SettleTracker`, over a whole series at once."""
    s = np.asarray(spool_pct, dtype=np.float64)
    q = np.asarray(qp_lpm, dtype=np.float64)
    if s.shape != q.shape or s.ndim != 1:
        raise InputFileError(f"SpoolCmd {s.shape} and QP {q.shape} must be one series each")
    idx = np.arange(s.size)
    with np.errstate(invalid="ignore"):
        out = np.isfinite(s) & np.isfinite(q) & (np.abs(s) > HOLD_PCT)
        stalled = out & (q < Q_STALL_LPM)
        moving = out & (q >= Q_STALL_LPM)
    # Length of the run of stalled samples ending at each sample (a NaN or a hold breaks it).
    since = idx - np.maximum.accumulate(np.where(stalled, -1, idx))
    event = np.where(stalled & (since >= N_STALL), 1, np.where(moving, -1, 0))
    last = np.maximum.accumulate(np.where(event != 0, idx, -1))
    return (last >= 0) & (event[np.maximum(last, 0)] == 1)


class SettleTracker:
    """:func:`settling_on_stop` one sample at a time (the live ticker's), in plain Python:
    a few comparisons per tick, no kernel to compile."""

    def __init__(self) -> None:
        self._run = 0
        self.on = False

    def push(self, spool_pct: float, qp_lpm: float) -> bool:
        """One sample; True while the rod settles on an end stop."""
        if abs(spool_pct) > HOLD_PCT and qp_lpm == qp_lpm:  # NaN compares False
            if qp_lpm < Q_STALL_LPM:
                self._run += 1
                self.on = self.on or self._run >= N_STALL
            else:
                self._run = 0
                self.on = False
        else:
            self._run = 0
        return self.on
