"""The full-lever statistic L: the pump pressure's (or, on a section of a shared
load-sensing pump, the section flow's) mean residual while the lever is near full stroke,
beside J and B.

A spool whose stroke is limited (a bent linkage, a pilot pressure too low, a stop screw)
acts only when the operator asks for more than it can open: on an excavator's boom cycle a
limit at 82 % of stroke is reached in a few seconds of a minute.  J, a 30 s mean of
squares over every output, dilutes those seconds about sixfold; B averages them with the
other regimes and outputs.  Yet in those seconds the pump pressure PP sits far from what
the healthy model predicts (an open-centre valve keeps its bypass partly open), some ten
times its normal scatter.  L keeps, over the last ``window_n`` valid samples, PP's mean
signed residual for the samples with the lever beyond ``FULL_PCT`` in each direction
(raising, lowering), and scales each by the largest such mean seen in held-out normal
operation:

    L = max over directions d with n_d >= min_count of |mean_d(e_PP)| / scale[d]

(a direction the held-out data never held at full lever long enough has an infinite scale
and is left out).

On the held-out data L is at most 1 by construction; its threshold l0 comes from the held-out
L by the same rule as eps0 from J (twice the largest, by default).  Like J and B, L is
judged only on a full window and a NaN residual pauses it.  One step kernel (``_push``)
serves the live ticker and the batch series.  Measured in docs/benchmarks.md ("The
full-lever statistic L").

On a section of a load-sensing pump shared by several loops (the whole excavator's
``section`` preset) PP is an input, not an output: the pump holds it at the highest load
plus its margin whatever one spool's opening.  There the post-compensated section's flow
is what the opening meters (flow = Kv x opening x sqrt(margin)), so a spool limited to
(1 - 0.6 s) of its stroke caps the section flow QP at that share of full flow whenever the
lever asks for more, with the port pressures unchanged (the compensator holds the drop).
The model, predicting QP from the lever, then predicts more than the section delivers at
every sample beyond the limit: L watches QP (``FLOW_OUTPUT``) on such a model, with the
same kernel, window and rule, and counts only a shortfall (``sign`` +1: the mean of
predicted minus measured, where positive).  A limit only takes flow away; normal work at
full lever departs both ways for a second at a time (a neighbour's move pulling the shared
pump into saturation, a spool's opening ramp): on the whole machine's held-out runs the
largest |mean| was 1.0-3.1 times the largest shortfall, and would have set the scale.
Measured in docs/benchmarks.md ("Stroke limits on the whole machine").
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from monitor.errors import ConfigError, InputFileError
from monitor.io.recording import Recording
from monitor.jit import jit
from monitor.model.fields import OMIT_AT_DEFAULT, fields_from_dict, fields_to_dict
from monitor.model.residual import largest_finite, resum_interval
from monitor.model.statistic import HeldOut, Statistic, column, register, signal
from monitor.signals import ROD_SPEED

#: Lever command (%) beyond which a sample counts for L: near full stroke, where a stroke
#: limit of severity 0.3 (82 %) or more acts on every sample that counts.
FULL_PCT = 80.0
#: The output L watches: the pump pressure, near-algebraic in the metering opening.
LEVER_OUTPUT = "PP"
#: ... or, on a model that takes PP as an input (a section of a shared load-sensing pump),
#: the section's flow, proportional to the opening.
FLOW_OUTPUT = "QP"
#: ... or, on a section model that predicts the rod's speed (``--rod-speed``), that speed:
#: the section's flow over the piston's area, less what leaks across a worn piston.  A stroke
#: limit slows the rod as it cuts the flow; a piston leak slows it with the flow unchanged,
#: most where the lever is full and the load high (the drop across the piston).
SPEED_OUTPUT = ROD_SPEED.name
N_DIRECTIONS = 2  # raising, lowering


def lever_directions(spool_pct: np.ndarray) -> np.ndarray:
    """Per sample: 0 (not counted), 1 (raising beyond ``FULL_PCT``), 2 (lowering beyond)."""
    s = np.asarray(spool_pct, dtype=np.float64)
    return np.where(s > FULL_PCT, 1, np.where(s < -FULL_PCT, 2, 0)).astype(np.int64)


def lever_direction(spool_pct: float) -> int:
    """``lever_directions`` for one sample (NaN: not counted)."""
    return 1 if spool_pct > FULL_PCT else 2 if spool_pct < -FULL_PCT else 0


@dataclass(frozen=True)
class LeverModel:
    """What the detector needs for L: window, the output, per-direction scales, l0."""

    window_n: int  # samples (6000: 60 s at 100 Hz)
    min_count: int  # samples beyond FULL_PCT in one direction before it counts
    output: int  # index of LEVER_OUTPUT (or FLOW_OUTPUT) among the model's outputs
    scale: np.ndarray  # (N_DIRECTIONS,), z-units: the largest held-out |mean|
    l0: float = float("nan")  # threshold; NaN: L is computed but never alarms
    #: 0: |mean| counts (PP: either way); 1: only a positive mean, the output measured
    #: below its prediction (QP: a section delivering less than the lever asks).
    sign: int = field(default=0, metadata=OMIT_AT_DEFAULT)  # two-sided files as before

    def __post_init__(self) -> None:
        if self.window_n < 2 or not 1 <= self.min_count <= self.window_n or self.output < 0:
            raise ConfigError(
                f"lever window {self.window_n}, min_count {self.min_count} and output "
                f"{self.output} must satisfy 1 <= min_count <= window, output >= 0"
            )
        if self.sign not in (0, 1):
            raise ConfigError(f"lever sign must be 0 (either way) or 1 (shortfall): {self.sign}")
        s = np.asarray(self.scale, dtype=np.float64)
        if s.shape != (N_DIRECTIONS,) or not np.all(s > 0):
            raise ConfigError(f"lever scale must be {N_DIRECTIONS} positive numbers, got {s}")
        object.__setattr__(self, "scale", np.ascontiguousarray(s))

    def to_dict(self) -> dict[str, object]:
        return fields_to_dict(self)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> LeverModel:
        return fields_from_dict(cls, d)


# State vector layout of the step kernel.
_POS, _COUNT, _PUSHES = 0, 1, 2


@jit(aot=True)
def _push(
    ring_e, ring_d, sums, counts, state, e, direction, output, scale, min_count, resum_every, sign
):  # pragma: no cover - numba
    """One sample into the window; returns L (NaN: paused, window not full, or no direction
    counted); ``sign`` 0: |mean|, 1: the positive part of the mean."""
    for o in range(e.shape[0]):
        if np.isnan(e[o]):
            return np.nan
    size = ring_d.shape[0]
    pos = state[_POS]
    if state[_COUNT] == size:  # full: the oldest sample leaves
        old = ring_d[pos]
        counts[old] -= 1.0
        sums[old] -= ring_e[pos]
    else:
        state[_COUNT] += 1
    ring_e[pos] = e[output]
    ring_d[pos] = direction
    sums[direction] += e[output]
    counts[direction] += 1.0
    state[_POS] = pos + 1 if pos + 1 < size else 0
    state[_PUSHES] += 1
    if state[_PUSHES] == resum_every:  # exact re-summation: add/subtract would drift
        state[_PUSHES] = 0
        sums[:] = 0.0
        for i in range(state[_COUNT]):
            sums[ring_d[i]] += ring_e[i]
    if state[_COUNT] < size:
        return np.nan
    out = np.nan
    for d in range(1, sums.shape[0]):  # 0: samples that do not count
        k = counts[d]
        if k >= min_count and scale[d - 1] < np.inf:  # inf: a direction left out
            m = sums[d] / k
            v = (abs(m) if sign == 0 else max(m, 0.0)) / scale[d - 1]
            if not v <= out:  # NaN-safe max
                out = v
    return out


@jit(aot=True)
def _series(e, directions, output, scale, window, min_count, resum_every, sign):  # pragma: no cover
    n = e.shape[0]
    out = np.empty(n)
    ring_e = np.zeros(window)
    ring_d = np.zeros(window, dtype=np.int64)
    sums = np.zeros(N_DIRECTIONS + 1)
    counts = np.zeros(N_DIRECTIONS + 1)
    state = np.zeros(3, dtype=np.int64)
    for i in range(n):
        out[i] = _push(
            ring_e,
            ring_d,
            sums,
            counts,
            state,
            e[i],
            directions[i],
            output,
            scale,
            min_count,
            resum_every,
            sign,
        )
    return out


def lever_series(e: np.ndarray, directions: np.ndarray, lever: LeverModel) -> np.ndarray:
    """L at every sample of residuals (samples, outputs) and their lever directions."""
    a = np.ascontiguousarray(e, dtype=np.float64)
    if a.ndim != 2 or not 0 <= lever.output < a.shape[1]:
        raise InputFileError(f"residuals {a.shape} have no output {lever.output} for L")
    d = np.ascontiguousarray(directions, dtype=np.int64)
    return _series(
        a,
        d,
        lever.output,
        lever.scale,
        lever.window_n,
        lever.min_count,
        resum_interval(lever.window_n),
        lever.sign,
    )


def fit_lever_scale(
    residuals: list[np.ndarray],
    directions: list[np.ndarray],
    window_n: int,
    min_count: int,
    output: int,
    sign: int = 0,
) -> np.ndarray:
    """Per direction, the largest |window mean| (``sign`` 1: positive window mean) of the
    output's residual over held-out normal data (the statistic's own windows: L's series
    with unit scales).  A direction that never counts there gets an infinite scale: L
    leaves it out (what normal operation does at that full lever is unknown), and a stroke
    limit, which caps the spool both ways, is judged in the other.  ``InputFileError``
    when neither direction counts: the held-out data never held the lever that far."""
    unit = LeverModel(window_n, min_count, output, np.ones(N_DIRECTIONS), sign=sign)
    # One direction at a time: the other direction's samples do not count.
    top = np.array(
        [
            largest_finite(
                lever_series(e, np.where(d == k + 1, d, 0), unit)
                for e, d in zip(residuals, directions, strict=True)
            )
            for k in range(N_DIRECTIONS)
        ]
    )
    if not np.any(top > 0):
        raise InputFileError(
            f"the held-out normal data never has {min_count / 100:g} s of lever beyond "
            f"{FULL_PCT:g} % in either direction within {window_n / 100:g} s: the full-lever "
            "statistic needs such data"
        )
    return np.where(top > 0, top, np.inf)


class LeverWindow:
    """L kept up to date one tick at a time (the live ticker's; same kernel as the series)."""

    def __init__(self, lever: LeverModel, spool_col: int = -1) -> None:
        self.lever = lever
        self._spool_col = spool_col  # SpoolCmd in a sampler row (-1: none, never counted)
        self._ring_e = np.zeros(lever.window_n)
        self._ring_d = np.zeros(lever.window_n, dtype=np.int64)
        self._sums = np.zeros(N_DIRECTIONS + 1)
        self._counts = np.zeros(N_DIRECTIONS + 1)
        self._state = np.zeros(3, dtype=np.int64)
        self._resum = resum_interval(lever.window_n)

    def push(self, e: np.ndarray, direction: int) -> float:
        """One sample's residuals (outputs) and lever direction; returns L."""
        lv = self.lever
        value = _push(
            self._ring_e,
            self._ring_d,
            self._sums,
            self._counts,
            self._state,
            e,
            direction,
            lv.output,
            lv.scale,
            lv.min_count,
            self._resum,
            lv.sign,
        )
        return float(value)

    def step(self, e: np.ndarray, row: np.ndarray) -> float:
        """One sampler row's residuals; the direction from its SpoolCmd; returns L."""
        spool = float(row[self._spool_col]) if self._spool_col >= 0 else 0.0
        lv = self.lever
        value = _push(
            self._ring_e,
            self._ring_d,
            self._sums,
            self._counts,
            self._state,
            e,
            lever_direction(spool),
            lv.output,
            lv.scale,
            lv.min_count,
            self._resum,
            lv.sign,
        )
        return float(value)


@register
class Lever(Statistic):
    """L as a member of the family: PP's (or a shared pump's section's QP's) mean residual
    with the lever near full stroke."""

    name = "L"
    key = "lever"
    threshold_key = "l0"
    title = "full-lever statistic L"
    colour = "tab:purple"
    counts = ("window_n", "min_count")
    order = 2

    def __init__(
        self, window_n: int = 6000, min_count: int = 100, output: int = 0, sign: int = 0
    ) -> None:
        self.window_n_setting = window_n
        self.min_count = min_count
        self.output = output
        self.sign = sign

    @classmethod
    def configure(cls, settings: Any, outputs: tuple[str, ...], on: set[str]) -> Lever | str:
        stats = settings.statistics
        if LEVER_OUTPUT in outputs:  # a loop on its own pump: with B, as it always was
            if "B" not in on:
                return "off (with the bias statistic, on a model that predicts PP)"
            return cls(stats.bias_window_n, stats.lever_min_count, outputs.index(LEVER_OUTPUT))
        if not settings.with_bias or FLOW_OUTPUT not in outputs:
            return "off (asked with the bias statistic, on a model that predicts PP or QP)"
        # A section of a shared pump: on its own support, not B's (the bucket's B is off for
        # its spread with oil temperature over every regime, which L's windows need not share).
        # A section model that predicts the rod's speed: L watches that (``SPEED_OUTPUT``).
        watched = SPEED_OUTPUT if SPEED_OUTPUT in outputs else FLOW_OUTPUT
        return cls(stats.bias_window_n, stats.flow_min_count, outputs.index(watched), 1)

    def unscaled(self, held: HeldOut) -> LeverModel:
        directions = [lever_directions(r["SpoolCmd"]) for r in held.recordings]
        scale = fit_lever_scale(
            list(held.residuals),
            directions,
            self.window_n_setting,
            self.min_count,
            self.output,
            self.sign,
        )
        return LeverModel(self.window_n_setting, self.min_count, self.output, scale, sign=self.sign)

    def series(self, e: np.ndarray, rec: Recording) -> np.ndarray:
        return lever_series(e, lever_directions(signal(rec, "SpoolCmd", 0.0)), self.params_)

    def window(self, columns: Sequence[str], n_out: int) -> LeverWindow:
        return LeverWindow(self.params_, column(columns, "SpoolCmd"))

    def coverage(self, held: HeldOut) -> dict[str, Any]:
        """Judged held-out samples with the lever beyond full, per direction."""
        counts = np.zeros(N_DIRECTIONS + 1, dtype=np.int64)
        for e, rec in zip(held.residuals, held.recordings, strict=True):
            ok = np.isfinite(e).all(axis=1)
            counts += np.bincount(lever_directions(rec["SpoolCmd"])[ok], minlength=N_DIRECTIONS + 1)
        return {"full_lever_samples": {"raise": int(counts[1]), "lower": int(counts[2])}}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> LeverModel:
        return LeverModel.from_dict(d)

    @classmethod
    def check_outputs(cls, params: LeverModel, n_out: int) -> None:
        if params.output >= n_out:
            raise ValueError(
                f"lever output {params.output} is not among the model's {n_out} outputs"
            )
