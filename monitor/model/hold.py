"""The hold statistic H: the cylinder pressures' mean residual in settled holds, beside J, B
and L.

A worn piston seal leaks oil across the piston (A <-> B).  While the lever is held the
valve is closed, and the leak is the one flow left: it drains the loaded chamber and fills
the other, a slow steady drift of PA and PB that the healthy machine does not have.  Nine
tenths of the fault's effect on the outputs is there, yet the one-step model predicts PA and
PB as increments from their own lagged values and sees the drift only as a small offset of
the residual.  J squares that offset into the scatter of every sample; B averages it with
the other outputs and the four moving regimes, some tenfold dilution.  Worse, in the first
two seconds of a hold the pressures still ring from the move that ended, and the model's
error there is larger than a slight leak's: measured on held-out normal data, the largest
60 s mean of PA's residual over hold samples falls fivefold once the first 2 s of every hold
are left out, while a leak's offset stays (docs/benchmarks.md, "The hold statistic H").

H keeps, over the last ``window_n`` valid samples, the mean signed residual of each watched
output (PA, PB) over the *settled hold* samples, and scales each by the largest such mean
seen in held-out normal operation.  Definition, per valid sample i (every output finite):

    hold_i    = |SpoolCmd_i| <= HOLD_PCT (a NaN command is not a hold), and, with the
                model's ``stroke``, the rod surely off the end stops (``monitor.model.endstop``:
                there the stop carries the load and the healthy model predicts badly)
    age_i     = consecutive valid hold samples up to and including i (0 when not hold_i)
    counted_i = age_i > settle_n
    n         = number of counted samples among the window's samples
    H         = max over watched outputs k of |sum of counted e_i[k]| / n / scale[k]
                (NaN until window_n valid samples were pushed, or while n < min_count)

A sample with a NaN residual (gated or missing) returns NaN, enters nothing and resets the
age: after a gap a hold settles again before it counts.  On the held-out data H is at most 1
by construction; its threshold h0 comes from the held-out H by the same rule as eps0 from J
(twice the largest, by default).  One step kernel (``_push``) serves the live ticker and the
batch series.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from monitor.errors import ConfigError, InputFileError
from monitor.io.recording import Recording
from monitor.jit import jit
from monitor.model.bias import HOLD_PCT
from monitor.model.endstop import (
    StopTracker,
    StrokeModel,
    check_stroke_section,
    fit_stroke,
    near_stop_series,
)
from monitor.model.fields import fields_from_dict, fields_to_dict
from monitor.model.filecheck import MAX_WINDOW_N, check_whole
from monitor.model.residual import largest_finite, resum_interval
from monitor.model.statistic import HeldOut, Statistic, column, register, signal

#: The outputs H watches: the cylinder chamber pressures, between which the piston leaks.
HOLD_OUTPUTS = ("PA", "PB")


def hold_flags(spool_pct: np.ndarray) -> np.ndarray:
    """Per sample: 1 where the lever is in hold (|SpoolCmd| <= ``HOLD_PCT``), else 0."""
    s = np.asarray(spool_pct, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return (np.abs(s) <= HOLD_PCT).astype(np.int64)  # NaN compares False: not a hold


def counted_holds(
    spool_pct: np.ndarray, qp_lpm: np.ndarray, stroke: StrokeModel | None
) -> np.ndarray:
    """Per sample: 1 where the lever is in hold and the rod is surely off the end stops
    (``monitor.model.endstop``; every hold when ``stroke`` is None), else 0."""
    flags = hold_flags(spool_pct)
    if stroke is None:
        return flags
    return flags & (1 - near_stop_series(spool_pct, qp_lpm, stroke))


@dataclass(frozen=True)
class HoldModel:
    """What the detector needs for H: window, settling, the outputs, their scales, h0."""

    window_n: int  # samples (6000: 60 s at 100 Hz)
    min_count: int  # settled hold samples in the window before H is judged
    settle_n: int  # hold samples (200: 2 s) before a hold's samples count
    outputs: tuple[int, ...]  # indices of HOLD_OUTPUTS among the model's outputs
    scale: np.ndarray  # (len(outputs),), z-units: the largest held-out |mean|
    h0: float = float("nan")  # threshold; NaN: H is computed but never alarms
    #: The end-stop estimate whose holds H leaves out (None: every hold counts; models
    #: trained before it existed).
    stroke: StrokeModel | None = None

    def __post_init__(self) -> None:
        if self.window_n < 2 or not 1 <= self.min_count <= self.window_n or self.settle_n < 0:
            raise ConfigError(
                f"hold window {self.window_n}, min_count {self.min_count} and settle "
                f"{self.settle_n} must satisfy 1 <= min_count <= window, settle >= 0"
            )
        outs = tuple(int(o) for o in self.outputs)
        if not outs or min(outs) < 0:
            raise ConfigError(f"hold outputs must be output indices, got {outs}")
        s = np.asarray(self.scale, dtype=np.float64)
        if s.shape != (len(outs),) or not np.all(np.isfinite(s) & (s > 0)):
            raise ConfigError(f"hold scale must be {len(outs)} positive numbers, got {s}")
        object.__setattr__(self, "outputs", outs)
        object.__setattr__(self, "scale", np.ascontiguousarray(s))

    def to_dict(self) -> dict[str, object]:
        return fields_to_dict(self)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> HoldModel:
        return fields_from_dict(cls, d)


# State vector layout of the step kernel.
_POS, _COUNT, _PUSHES, _AGE, _COUNTED = 0, 1, 2, 3, 4
_STATE = 5


@jit(aot=True)
def _push(
    ring_e, ring_c, sums, state, e, hold, outputs, scale, settle_n, min_count, resum_every
):  # pragma: no cover - numba
    """One sample into the window; returns H (NaN: paused, window not full, or too few
    settled hold samples)."""
    for o in range(e.shape[0]):
        if np.isnan(e[o]):
            state[_AGE] = 0  # after a gap the hold settles again
            return np.nan
    state[_AGE] = state[_AGE] + 1 if hold else 0
    counted = 1 if state[_AGE] > settle_n else 0
    size = ring_c.shape[0]
    n_k = outputs.shape[0]
    pos = state[_POS]
    if state[_COUNT] == size:  # full: the oldest sample leaves
        if ring_c[pos]:
            state[_COUNTED] -= 1
            for k in range(n_k):
                sums[k] -= ring_e[pos, k]
    else:
        state[_COUNT] += 1
    ring_c[pos] = counted
    for k in range(n_k):
        ring_e[pos, k] = e[outputs[k]] if counted else 0.0
        sums[k] += ring_e[pos, k]
    state[_COUNTED] += counted
    state[_POS] = pos + 1 if pos + 1 < size else 0
    state[_PUSHES] += 1
    if state[_PUSHES] == resum_every:  # exact re-summation: add/subtract would drift
        state[_PUSHES] = 0
        sums[:] = 0.0
        for i in range(state[_COUNT]):
            for k in range(n_k):
                sums[k] += ring_e[i, k]
    n = state[_COUNTED]
    if state[_COUNT] < size or n < min_count:
        return np.nan
    out = 0.0
    for k in range(n_k):
        v = abs(sums[k] / n) / scale[k]
        if v > out:
            out = v
    return out


@jit(aot=True)
def _series(
    e, flags, outputs, scale, window, settle_n, min_count, resum_every
):  # pragma: no cover - numba
    n = e.shape[0]
    out = np.empty(n)
    ring_e = np.zeros((window, outputs.shape[0]))
    ring_c = np.zeros(window, dtype=np.int64)
    sums = np.zeros(outputs.shape[0])
    state = np.zeros(_STATE, dtype=np.int64)
    for i in range(n):
        out[i] = _push(
            ring_e,
            ring_c,
            sums,
            state,
            e[i],
            flags[i],
            outputs,
            scale,
            settle_n,
            min_count,
            resum_every,
        )
    return out


def hold_series(e: np.ndarray, flags: np.ndarray, hold: HoldModel) -> np.ndarray:
    """H at every sample of residuals (samples, outputs) and their hold flags."""
    a = np.ascontiguousarray(e, dtype=np.float64)
    if a.ndim != 2 or max(hold.outputs) >= a.shape[1]:
        raise InputFileError(f"residuals {a.shape} have no outputs {hold.outputs} for H")
    f = np.ascontiguousarray(flags, dtype=np.int64)
    outs = np.asarray(hold.outputs, dtype=np.int64)
    return _series(
        a,
        f,
        outs,
        hold.scale,
        hold.window_n,
        hold.settle_n,
        hold.min_count,
        resum_interval(hold.window_n),
    )


def fit_hold_scale(
    residuals: list[np.ndarray],
    flags: list[np.ndarray],
    window_n: int,
    min_count: int,
    settle_n: int,
    outputs: tuple[int, ...],
) -> np.ndarray:
    """Per watched output, the largest |window mean| of its residual over held-out normal
    data (the statistic's own windows: H's series with that output alone, unit scale).
    ``InputFileError`` when no window has ``min_count`` settled hold samples: the held-out
    data never held the lever long enough."""
    units = [HoldModel(window_n, min_count, settle_n, (o,), np.ones(1)) for o in outputs]
    top = np.array(
        [
            largest_finite(hold_series(e, f, unit) for e, f in zip(residuals, flags, strict=True))
            for unit in units
        ]
    )
    if not np.all(top > 0):
        raise InputFileError(
            f"the held-out normal data never has {min_count / 100:g} s of holds settled for "
            f"{settle_n / 100:g} s within {window_n / 100:g} s: the hold statistic needs such "
            "data"
        )
    return top


class HoldWindow:
    """H kept up to date one tick at a time (the live ticker's; same kernel as the series)."""

    def __init__(self, hold: HoldModel, spool_col: int = -1, qp_col: int = -1) -> None:
        self.hold = hold
        self._spool_col, self._qp_col = spool_col, qp_col  # in a sampler row (-1: none)
        self._stops = None if hold.stroke is None else StopTracker(hold.stroke)
        self._ring_e = np.zeros((hold.window_n, len(hold.outputs)))
        self._ring_c = np.zeros(hold.window_n, dtype=np.int64)
        self._sums = np.zeros(len(hold.outputs))
        self._state = np.zeros(_STATE, dtype=np.int64)
        self._outputs = np.asarray(hold.outputs, dtype=np.int64)
        self._resum = resum_interval(hold.window_n)

    def push(self, e: np.ndarray, spool_pct: float, qp_lpm: float) -> float:
        """One sample's residuals (outputs), SpoolCmd (%) and QP (L/min); returns H."""
        h = self.hold
        # The tracker sees every sample, a hold or not: the rod's travel is in the moves.
        near = 0 if self._stops is None else self._stops.push(spool_pct, qp_lpm)
        flag = 1 if abs(spool_pct) <= HOLD_PCT and not near else 0
        value = _push(
            self._ring_e,
            self._ring_c,
            self._sums,
            self._state,
            e,
            flag,
            self._outputs,
            h.scale,
            h.settle_n,
            h.min_count,
            self._resum,
        )
        return float(value)

    def step(self, e: np.ndarray, row: np.ndarray) -> float:
        """One sampler row's residuals, its SpoolCmd (0 without) and QP (NaN without)."""
        spool = float(row[self._spool_col]) if self._spool_col >= 0 else 0.0
        qp = float(row[self._qp_col]) if self._qp_col >= 0 else np.nan
        return self.push(e, spool, qp)


@register
class Hold(Statistic):
    """H as a member of the family: PA's and PB's mean residual in settled holds."""

    name = "H"
    key = "hold"
    threshold_key = "h0"
    title = "hold statistic H"
    colour = "tab:brown"
    counts = ("window_n", "min_count")
    order = 3
    asked_by = "hold"

    def __init__(
        self,
        window_n: int = 6000,
        min_count: int = 300,
        settle_n: int = 200,
        outputs: tuple[int, ...] = (1, 2),
    ) -> None:
        self.window_n_setting = window_n
        self.min_count = min_count
        self.settle_n = settle_n
        self.outputs = outputs

    @classmethod
    def configure(cls, settings: Any, outputs: tuple[str, ...], on: set[str]) -> Hold | str:
        if not settings.statistics.hold:
            return "off (not asked for: --hold on)"
        if "B" not in on or not all(o in outputs for o in HOLD_OUTPUTS):
            return "off (with the bias statistic, on a model that predicts PA and PB)"
        return cls(
            settings.statistics.bias_window_n,
            settings.statistics.hold_min_count,
            settings.statistics.hold_settle_n,
            tuple(outputs.index(o) for o in HOLD_OUTPUTS),
        )

    def unscaled(self, held: HeldOut) -> HoldModel:
        # The boom cylinder's swept volumes from every normal recording given: geometry,
        # not a threshold, so the training part counts too.  Holds on an end stop are left
        # out: the healthy model predicts them badly, and a machine lowered into its stop
        # raised false alarms (``monitor.model.endstop``).
        every = held.every or held.recordings
        stroke = fit_stroke([r["SpoolCmd"] for r in every], [r["QP"] for r in every])
        flags = [counted_holds(r["SpoolCmd"], r["QP"], stroke) for r in held.recordings]
        scale = fit_hold_scale(
            list(held.residuals),
            flags,
            self.window_n_setting,
            self.min_count,
            self.settle_n,
            self.outputs,
        )
        return HoldModel(
            self.window_n_setting, self.min_count, self.settle_n, self.outputs, scale, stroke=stroke
        )

    def series(self, e: np.ndarray, rec: Recording) -> np.ndarray:
        flags = counted_holds(
            signal(rec, "SpoolCmd", 0.0), signal(rec, "QP", np.nan), self.params_.stroke
        )
        return hold_series(e, flags, self.params_)

    def window(self, columns: Sequence[str], n_out: int) -> HoldWindow:
        return HoldWindow(self.params_, column(columns, "SpoolCmd"), column(columns, "QP"))

    def coverage(self, held: HeldOut) -> dict[str, Any]:
        """Judged held-out samples in holds off the end stops."""
        n = 0
        for e, rec in zip(held.residuals, held.recordings, strict=True):
            flags = counted_holds(rec["SpoolCmd"], rec["QP"], self.params_.stroke)
            n += int(np.sum(flags[np.isfinite(e).all(axis=1)]))
        return {"hold_samples": n}

    @classmethod
    def warm(cls) -> None:
        # H is opt-in for `monitor train` (``--hold on``): the configured model may lack it.
        hold = HoldModel(2, 1, 0, (1, 2), np.ones(2), stroke=StrokeModel(1.0, 1.0))
        hold_series(np.zeros((4, 4)), counted_holds(np.zeros(4), np.zeros(4), hold.stroke), hold)
        HoldWindow(hold).push(np.zeros(4), 0.0, 0.0)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> HoldModel:
        return HoldModel.from_dict(d)

    @classmethod
    def check_outputs(cls, params: HoldModel, n_out: int) -> None:
        if max(params.outputs) >= n_out:
            raise ValueError(
                f"hold outputs {params.outputs} are not among the model's {n_out} outputs"
            )

    @classmethod
    def check_more(cls, section: dict[str, Any]) -> None:
        check_whole(section, "settle_n", 0, MAX_WINDOW_N, "hold.")
        if section.get("stroke") is not None:
            check_stroke_section(section["stroke"], "hold.stroke")
