"""The flow-continuity statistic F: the pump's flow beyond what the rod's speed takes, while
the boom lowers steadily, beside J, B, L and H.

A worn piston seal leaks oil across the piston.  While the boom lowers the pump feeds the
rod side, above the cap side's pressure (the cap side meters the load out), so part of the
pump's flow goes through the seal into the cap side instead of moving the rod: the pump
delivers more than the rod side's area times the rod's speed.  Continuity says so whatever
the model predicts, so F reads the measured signals alone (QP, RodPos, SpoolCmd), not the
DGRNN's residuals: those predict PA and PB from their own lags and see a leak only as a
small offset among the moves' scatter (``monitor.model.hold``).  Measured on the outsider's
plant (benchmarks/detect_blind, development seed 1, +-5 %): QP on the rod's speed, fitted on
the commissioning run, left 2-minute means of -0.15..+0.07 L/min on 12 normal logs of other
loads and operators and +0.23..+0.28 L/min on piston wear of severity 0.3 and 0.5.

Per sample i (``ROD_SPEED_SPAN`` = 10 samples, 0.1 s):

    v_i       = (RodPos_i - RodPos_{i-10}) / 0.1 s                    (mm/s, < 0: lowering)
    counted_i = the last 21 samples valid (finite, judged), SpoolCmd < -LOWER_PCT on the
                last 11, v_i < -MIN_SPEED, |v_i - v_{i-10}| < STEADY (no start, stop or
                bounce), RodPos_i and RodPos_{i-10} more than STOP_MARGIN within the stroke
                the normal data spans (the stops carry the load there)
    excess_i  = mean(QP_{i-9..i}) - (a + b |v_i|)                     (L/min)
    F         = max(0, mean of the last ``count_n`` counted excess_i) / scale

in standard errors: ``scale`` (L/min) is the standard deviation of the held-out excess over
the square root of the window's independent samples, ``count_n`` / 10 (the speed's span
makes ten neighbours share their RodPos readings).

``a`` and ``b`` (the healthy flow at a lowering speed: leakage and meter offset, and the
rod side's area) are fitted by least squares on the counted samples of every normal
recording given to training: the line is the machine's geometry, two numbers from
thousands of samples.  F is judged once ``count_n`` samples have counted and keeps its
value between lowerings (the evidence stands until new lowering moves it); a sample with a
NaN residual (gated) returns NaN and restarts the runs above, not the window.  A sample the
model's envelope gated for its OilTemp alone is judged too when that oil lies in F's own oil
range (``oil_lo_c``..``oil_hi_c``, ``monitor.model.flow_oil``: commissioning's lowerings show
how little continuity moves with the oil); there J is not judged and F sets the level alone.
The kernel decides which samples it judges (``_judged``) from the residuals and that oil, the
same test offline and per tick.

Its threshold f0 comes from the statistic's own held-out values, the line cross-fitted over
the normal recordings (60 s blocks dealt to ``FOLDS`` folds, each judged by the line fitted
on the others), by the same rule as eps0 from J, and is at least ``MIN_SCORE``: 20 minutes
of commissioning hold some 70 s of steady lowering, three or four windows, and their
largest says little of the tail; the standard error rests on every lowering sample.  So F's
support is its standard error, not its windows: it needs neither the training's eight
independent windows nor two sessions (``min_windows``, ``min_sessions``); the transfer
check (fitted on one half of the data, judged on the other) stands.

An alarm F raises is named ``piston_wear`` (``Statistic.names``): no other fault of the loop
makes the pump deliver more than the rod takes with the valve open (spool wear opens the
lands near centre, not at a lowering lever; a stroke limit caps the flow and the speed
together).  One step kernel (``_push``) serves the live ticker and the batch series.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from monitor.errors import ConfigError, InputFileError
from monitor.io.recording import Recording
from monitor.jit import jit
from monitor.model.fields import fields_from_dict, fields_to_dict
from monitor.model.filecheck import MAX_WINDOW_N, check_number, check_whole
from monitor.model.flow_oil import OIL_SHARE, oil_trend
from monitor.model.residual import resum_interval
from monitor.model.statistic import HeldOut, Statistic, column, register, signal
from monitor.model.threshold import ThresholdRule
from monitor.signals import ROD_POS, ROD_SPEED_SPAN, SAMPLE_PERIOD_S

#: Spool command (%) beyond which lowering counts: the metering edge well open (the
#: valves' overlaps end at some 6 % of stroke), the rod's speed set by the lever.
LOWER_PCT = 20.0
#: Rod speed (mm/s) below which a lowering does not count: RodPos over 0.1 s scatters by
#: some 7 mm/s (``monitor.signals.ROD_SPEED_SPAN``).
MIN_SPEED_MM_S = 10.0
#: Largest change of the speed over 0.1 s (mm/s) of a steady lowering: starts, stops and a
#: bouncing boom fill and empty the chambers' compliance, which continuity does not see.
STEADY_MM_S = 15.0
#: Distance (mm) from the stroke's ends the normal data reached within which nothing counts.
STOP_MARGIN_MM = 25.0
#: Samples of history a counted sample needs: RodPos now, 0.1 s and 0.2 s before.
HISTORY = 2 * ROD_SPEED_SPAN + 1
#: Engine speed (rpm) below which a sample of the training data is not used (the alarm's
#: default ``min_engine_rpm``: the monitor is inactive there).
RUNNING_RPM = 500.0
#: The least threshold, in standard errors of a window's mean: a one-sided normal tail of
#: 3e-5 per window.  The largest of the few windows 20 minutes of commissioning hold is one
#: or two standard errors, and the normal logs' maxima on the outsider's plant
#: (development seeds 1-3, 2 h per machine) reached 2.7.
MIN_SCORE = 4.0
#: Folds the line is cross-fitted in for the threshold, and their blocks (samples).
FOLDS = 4
FOLD_BLOCK_N = 6000


@dataclass(frozen=True)
class FlowModel:
    """What the detector needs for F: the healthy line, the stroke, the window, f0."""

    count_n: int  # counted lowering samples averaged (2000: 20 s of steady lowering)
    window_n: int  # samples one window of count_n counted samples spans (threshold blocks)
    a_lpm: float  # healthy QP at zero lowering speed, L/min
    b_lpm_per_mm_s: float  # healthy QP per mm/s of lowering speed, L/min / (mm/s)
    lo_mm: float  # the stroke's ends in the normal data, mm
    hi_mm: float
    scale: float  # L/min: the standard error of a window's mean on the held-out data
    f0: float = float("nan")  # threshold; NaN: F is computed but never alarms
    #: F's own oil range (degC, ``oil_range``): a sample the envelope gates for its OilTemp
    #: alone is judged by F when its oil lies in it.  NaN (model files before it): F judges
    #: only where J does.
    oil_lo_c: float = float("nan")
    oil_hi_c: float = float("nan")

    def __post_init__(self) -> None:
        if not 1 <= self.count_n <= MAX_WINDOW_N or not 1 <= self.window_n <= MAX_WINDOW_N:
            raise ConfigError(
                f"flow count {self.count_n} and window {self.window_n} must be 1..{MAX_WINDOW_N}"
            )
        numbers = (self.a_lpm, self.b_lpm_per_mm_s, self.lo_mm, self.hi_mm)
        if not all(np.isfinite(numbers)) or not self.lo_mm < self.hi_mm:
            raise ConfigError(f"flow line and stroke must be finite, lo < hi: {numbers}")
        if not self.scale > 0 or not np.isfinite(self.scale):
            raise ConfigError(f"flow scale must be a positive number, got {self.scale}")
        if self.oil_lo_c > self.oil_hi_c:
            raise ConfigError(f"flow oil range {self.oil_lo_c}..{self.oil_hi_c} degC is empty")

    def to_dict(self) -> dict[str, object]:
        return fields_to_dict(self)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> FlowModel:
        return fields_from_dict(cls, d)


# Integer state of the step kernel.
_POS_X, _POS_Q, _VALID, _LOW, _POS_W, _COUNT, _PUSHES = 0, 1, 2, 3, 4, 5, 6
_STATE = 7
# Float state: the window's sum, F at the last counted sample, and the last feature.
_SUM, _LAST, _SPEED, _QMEAN = 0, 1, 2, 3
_FSTATE = 4


@jit(aot=True)
def _feature(ring_x, ring_q, state, fstate, spool, rod, qp, ok, lo, hi):  # pragma: no cover
    """One sample into the speed and flow rings; 1 when it counts (its lowering speed and
    mean QP then in ``fstate``), else 0."""
    if not ok or np.isnan(spool) or np.isnan(rod) or np.isnan(qp):
        state[_VALID] = 0
        state[_LOW] = 0
        return 0
    span = ring_q.shape[0]
    hist = ring_x.shape[0]
    px = state[_POS_X]
    ring_x[px] = rod
    state[_POS_X] = px + 1 if px + 1 < hist else 0
    pq = state[_POS_Q]
    ring_q[pq] = qp
    state[_POS_Q] = pq + 1 if pq + 1 < span else 0
    state[_VALID] += 1
    state[_LOW] = state[_LOW] + 1 if spool < -LOWER_PCT else 0
    if state[_VALID] < hist or state[_LOW] < span + 1:
        return 0
    x10 = ring_x[(px - span) % hist]
    x20 = ring_x[(px - 2 * span) % hist]
    dt = span * SAMPLE_PERIOD_S
    v = (rod - x10) / dt
    v_before = (x10 - x20) / dt
    if not v < -MIN_SPEED_MM_S or not abs(v - v_before) < STEADY_MM_S:
        return 0
    if min(rod, x10) <= lo + STOP_MARGIN_MM or max(rod, x10) >= hi - STOP_MARGIN_MM:
        return 0
    total = 0.0
    for k in range(span):
        total += ring_q[k]
    fstate[_SPEED] = -v
    fstate[_QMEAN] = total / span
    return 1


@jit(aot=True)
def _judged(e, beyond_c, oil_lo, oil_hi):  # pragma: no cover - numba
    """F judges a sample where J does (every residual finite), and where the envelope gated
    it for its OilTemp alone (``beyond_c``, that oil in degC; NaN: not so gated) with the
    oil inside F's own range."""
    if beyond_c >= oil_lo and beyond_c <= oil_hi:  # False with a NaN
        return True
    missing = 0
    for o in range(e.shape[0]):
        missing += np.isnan(e[o])
    return missing == 0


@jit(aot=True)
def _push(
    ring_x,
    ring_q,
    ring_w,
    state,
    fstate,
    e,
    beyond_c,
    spool,
    rod,
    qp,
    a,
    b,
    lo,
    hi,
    oil_lo,
    oil_hi,
    scale,
    resum_every,
):  # pragma: no cover - numba
    """One sample (its residuals ``e`` and ``beyond_c``: see ``_judged``); returns F (NaN: a
    sample not judged or incomplete, or fewer than ``count_n`` counted yet)."""
    ok = _judged(e, beyond_c, oil_lo, oil_hi)
    if not ok or np.isnan(spool) or np.isnan(rod) or np.isnan(qp):
        state[_VALID] = 0  # the runs start again; the window stays
        state[_LOW] = 0
        return np.nan
    if _feature(ring_x, ring_q, state, fstate, spool, rod, qp, ok, lo, hi):
        size = ring_w.shape[0]
        pos = state[_POS_W]
        excess = fstate[_QMEAN] - (a + b * fstate[_SPEED])
        if state[_COUNT] == size:  # full: the oldest counted sample leaves
            fstate[_SUM] -= ring_w[pos]
        else:
            state[_COUNT] += 1
        ring_w[pos] = excess
        fstate[_SUM] += excess
        state[_POS_W] = pos + 1 if pos + 1 < size else 0
        state[_PUSHES] += 1
        if state[_PUSHES] == resum_every:  # exact re-summation: add/subtract would drift
            state[_PUSHES] = 0
            fstate[_SUM] = 0.0
            for i in range(state[_COUNT]):
                fstate[_SUM] += ring_w[i]
        if state[_COUNT] == size:
            fstate[_LAST] = max(fstate[_SUM] / size, 0.0) / scale
    return fstate[_LAST]


def _fresh(count_n: int) -> tuple[np.ndarray, ...]:
    """A window's empty state: RodPos and QP rings, the counted ring, integer, float state."""
    fstate = np.zeros(_FSTATE)
    fstate[_LAST] = np.nan
    return (
        np.zeros(HISTORY),
        np.zeros(ROD_SPEED_SPAN),
        np.zeros(count_n),
        np.zeros(_STATE, dtype=np.int64),
        fstate,
    )


@jit(aot=True)
def _series(
    e,
    beyond_c,
    spool,
    rod,
    qp,
    a,
    b,
    lo,
    hi,
    oil_lo,
    oil_hi,
    scale,
    ring_x,
    ring_q,
    ring_w,
    state,
    fstate,
    resum_every,
):  # pragma: no cover - numba
    n = spool.shape[0]
    out = np.empty(n)
    for i in range(n):
        out[i] = _push(
            ring_x,
            ring_q,
            ring_w,
            state,
            fstate,
            e[i],
            beyond_c[i],
            spool[i],
            rod[i],
            qp[i],
            a[i],
            b[i],
            lo,
            hi,
            oil_lo,
            oil_hi,
            scale,
            resum_every,
        )
    return out


@jit(aot=True)
def _features(spool, rod, qp, ok, lo, hi, ring_x, ring_q, state, fstate):  # pragma: no cover
    n = spool.shape[0]
    counted = np.zeros(n, dtype=np.int64)
    speed = np.full(n, np.nan)
    qmean = np.full(n, np.nan)
    for i in range(n):
        if _feature(ring_x, ring_q, state, fstate, spool[i], rod[i], qp[i], ok[i], lo, hi):
            counted[i] = 1
            speed[i] = fstate[_SPEED]
            qmean[i] = fstate[_QMEAN]
    return counted, speed, qmean


def _arrays(rec: Recording) -> tuple[np.ndarray, ...]:
    return (
        np.ascontiguousarray(signal(rec, "SpoolCmd", 0.0), dtype=np.float64),
        np.ascontiguousarray(signal(rec, ROD_POS.name, np.nan), dtype=np.float64),
        np.ascontiguousarray(signal(rec, "QP", np.nan), dtype=np.float64),
    )


def lowering_features(
    rec: Recording, ok: np.ndarray, lo_mm: float, hi_mm: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per sample of a recording (``ok``: judged): counted (0/1), lowering speed (mm/s) and
    mean QP over the speed's span (L/min), NaN where not counted."""
    ring_x, ring_q, _, state, fstate = _fresh(1)
    # Boolean, as ``_push`` passes it: one compiled signature per kernel (the controller's
    # ahead-of-time module takes exactly one).
    judged = np.ascontiguousarray(ok, dtype=np.bool_)
    return _features(*_arrays(rec), judged, lo_mm, hi_mm, ring_x, ring_q, state, fstate)


def judged_only(ok: np.ndarray) -> np.ndarray:
    """Residuals (samples, 1) that say ``ok`` and nothing else: 0 where judged, NaN where
    not (training's running samples, the fit's own held-out data)."""
    return np.where(np.asarray(ok, dtype=bool), 0.0, np.nan)[:, None]


def flow_series(
    rec: Recording,
    e: np.ndarray,
    flow: FlowModel,
    beyond_c: np.ndarray | None = None,
    a_lpm: np.ndarray | None = None,
    b_lpm_per_mm_s: np.ndarray | None = None,
) -> np.ndarray:
    """F at every sample of a recording: judged where its residuals ``e`` (samples, outputs)
    are finite, and where ``beyond_c`` (the envelope gated the sample for its OilTemp alone:
    that oil, degC; NaN elsewhere) lies in F's own oil range; ``a_lpm``/``b_lpm_per_mm_s``
    per sample (a cross-fitted line) instead of the model's."""
    n = len(rec)
    a = np.full(n, flow.a_lpm) if a_lpm is None else np.ascontiguousarray(a_lpm, np.float64)
    b = (
        np.full(n, flow.b_lpm_per_mm_s)
        if b_lpm_per_mm_s is None
        else np.ascontiguousarray(b_lpm_per_mm_s, np.float64)
    )
    beyond = np.full(n, np.nan) if beyond_c is None else np.ascontiguousarray(beyond_c, np.float64)
    rings = _fresh(flow.count_n)
    return _series(
        np.ascontiguousarray(e, dtype=np.float64),
        beyond,
        *_arrays(rec),
        a,
        b,
        flow.lo_mm,
        flow.hi_mm,
        flow.oil_lo_c,
        flow.oil_hi_c,
        flow.scale,
        *rings,
        resum_interval(flow.count_n),
    )


def fit_line(speed: np.ndarray, qmean: np.ndarray) -> tuple[float, float]:
    """(a, b): least squares of QP = a + b * speed over the counted samples given."""
    design = np.column_stack([np.ones(len(speed)), speed])
    (a, b), *_ = np.linalg.lstsq(design, qmean, rcond=None)
    return float(a), float(b)


def running(rec: Recording) -> np.ndarray:
    """Samples of a training recording with the engine running (judged by the monitor)."""
    return signal(rec, "EngineSpeed", np.nan) >= RUNNING_RPM


class FlowWindow:
    """F kept up to date one tick at a time (the live ticker's; same kernel as the series)."""

    def __init__(
        self, flow: FlowModel, spool_col: int = -1, rod_col: int = -1, qp_col: int = -1
    ) -> None:
        self.flow = flow
        self._cols = (spool_col, rod_col, qp_col)  # in a sampler row (-1: none)
        self._rings = _fresh(flow.count_n)
        self._resum = resum_interval(flow.count_n)

    def push(
        self, e: np.ndarray, beyond_c: float, spool_pct: float, rod_mm: float, qp_lpm: float
    ) -> float:
        """One sample: its residuals ``e`` (float64, outputs), ``beyond_c`` (its OilTemp,
        degC, where the envelope gated it for that alone; NaN elsewhere), SpoolCmd (%),
        RodPos (mm), QP (L/min); returns F."""
        f = self.flow
        value = _push(
            *self._rings,
            e,
            beyond_c,
            spool_pct,
            rod_mm,
            qp_lpm,
            f.a_lpm,
            f.b_lpm_per_mm_s,
            f.lo_mm,
            f.hi_mm,
            f.oil_lo_c,
            f.oil_hi_c,
            f.scale,
            self._resum,
        )
        return float(value)

    def step(self, e: np.ndarray, row: np.ndarray) -> float:
        """One sampler row, judged where every residual is finite."""
        return self.step_beyond(e, row, np.nan)

    def step_beyond(self, e: np.ndarray, row: np.ndarray, beyond_c: float) -> float:
        """One sampler row, also judged where the envelope gated it for its OilTemp alone
        (``beyond_c``, degC) inside F's own oil range."""
        s, x, q = (float(row[c]) if c >= 0 else np.nan for c in self._cols)
        return self.push(e, beyond_c, s, x, q)


@register
class Flow(Statistic):
    """F as a member of the family: the pump's flow beyond the rod's speed while lowering."""

    name = "F"
    key = "flow"
    threshold_key = "f0"
    title = "flow-continuity statistic F"
    colour = "tab:olive"
    counts = ("window_n", "count_n")
    order = 4
    names = "piston_wear"
    own_held_out = True
    #: Its threshold rests on the standard error of every lowering sample (``MIN_SCORE``),
    #: not on the largest of its few windows: one session and one window will do.
    min_sessions = 1
    min_windows = 1
    #: Continuity moves with the oil only through the leakage: F judges warm oil the model's
    #: envelope leaves out, on its own range (``monitor.model.flow_oil``).
    beyond_oil = True

    def __init__(self, count_n: int = 2000) -> None:
        self.count_n = count_n

    @classmethod
    def configure(cls, settings: Any, outputs: tuple[str, ...], on: set[str]) -> Flow | str:
        if not settings.with_bias:
            return "off (not the paper's method: with the bias statistic's presets)"
        if "PP" not in outputs or "QP" not in outputs:
            return "off (on a loop with its own pump: a model that predicts PP and QP)"
        return cls()

    def unscaled(self, held: HeldOut) -> FlowModel:
        """The line on every counted sample of ``held``'s recordings, the stroke they span,
        and the scale from the line cross-fitted over them (``FOLDS`` folds of 60 s blocks);
        keeps the cross-fitted series (unit scale) for :meth:`fit`'s threshold."""
        recs = list(held.recordings)
        if not recs or not all(r.has(ROD_POS.name) for r in recs):
            raise InputFileError(
                "the normal data has no RodPos: the flow-continuity statistic needs the "
                "rod's position"
            )
        ok = [
            running(r) & np.isfinite(e).all(axis=1)
            for r, e in zip(recs, held.residuals, strict=True)
        ]
        lo = min(float(np.nanmin(r[ROD_POS.name])) for r in recs)
        hi = max(float(np.nanmax(r[ROD_POS.name])) for r in recs)
        feats = [lowering_features(r, k, lo, hi) for r, k in zip(recs, ok, strict=True)]
        counted = sum(int(c.sum()) for c, _, _ in feats)
        if counted < 2 * self.count_n:
            raise InputFileError(
                f"the normal data has {counted / 100:.0f} s of steady lowering away from the "
                f"stops; the flow-continuity statistic needs at least "
                f"{2 * self.count_n / 100:g} s"
            )
        a, b = fit_line(*_all(feats))
        judged = sum(int(k.sum()) for k in ok)
        span = min(MAX_WINDOW_N, max(self.count_n, round(self.count_n * judged / counted)))
        folds = _folds(recs, feats)
        excess = np.concatenate(
            [(q - (fa + fb * s))[c == 1] for (c, s, q), (fa, fb) in zip(feats, folds, strict=True)]
        )
        unit = FlowModel(self.count_n, span, a, b, lo, hi, 1.0)
        self._held = [
            flow_series(r, judged_only(k), unit, None, fa, fb)
            for r, k, (fa, fb) in zip(recs, ok, folds, strict=True)
        ]
        self._oil = oil_trend(recs, feats, a, b)
        top = max((float(np.nanmax(p)) for p in self._held if np.isfinite(p).any()), default=0.0)
        standard_error = float(np.std(excess)) / np.sqrt(self.count_n / ROD_SPEED_SPAN)
        self._notes = {
            "line_lpm": [round(a, 4), round(b, 5)],
            "standard_error_lpm": round(standard_error, 4),
            "largest_mean_lpm": round(top, 4),
            "lowering_s": round(counted / 100, 1),
        }
        return FlowModel(self.count_n, span, a, b, lo, hi, standard_error)

    def fit(self, held: HeldOut, rule: ThresholdRule) -> Flow:
        """As every member's, but the held-out values are the cross-fitted line's, and the
        threshold is at least ``MIN_SCORE`` standard errors."""
        self.params_ = self.unscaled(held)
        parts = [p / self.params_.scale for p in self._held]
        _, threshold = rule.eps0(np.concatenate(parts), block=self.window_n)
        self.params_ = self.with_threshold(max(threshold, MIN_SCORE))
        allowance_lpm = OIL_SHARE * self.params_.f0 * self.params_.scale
        oil_lo, oil_hi = self._oil.range_c(allowance_lpm)
        self.params_ = dataclasses.replace(self.params_, oil_lo_c=oil_lo, oil_hi_c=oil_hi)
        self.support_ = self.support(held, parts)
        self.support_["oil_range"] = self._oil.said(allowance_lpm, oil_lo, oil_hi)
        if threshold < MIN_SCORE:
            self.support_["floor"] = (
                f"f0 {threshold:.3g} -> {MIN_SCORE:g} standard errors of a window's mean "
                f"({MIN_SCORE * self.params_.scale:.3g} L/min)"
            )
        return self

    def series(self, e: np.ndarray, rec: Recording) -> np.ndarray:
        return self.series_beyond(e, rec, None)

    def series_beyond(
        self, e: np.ndarray, rec: Recording, beyond_c: np.ndarray | None
    ) -> np.ndarray:
        if not rec.has(ROD_POS.name):
            return np.full(len(rec), np.nan)
        return flow_series(rec, e, self.params_, beyond_c)

    def window(self, columns: Sequence[str], n_out: int) -> FlowWindow:
        return FlowWindow(
            self.params_,
            column(columns, "SpoolCmd"),
            column(columns, ROD_POS.name),
            column(columns, "QP"),
        )

    def coverage(self, held: HeldOut) -> dict[str, Any]:
        """The line, its standard error and the lowering it rests on (L/min, s)."""
        return dict(self._notes)

    @classmethod
    def warm(cls) -> None:
        flow = FlowModel(2, 2, 0.0, 0.1, 0.0, 500.0, 1.0)
        n = HISTORY + 4
        rec = Recording(
            np.arange(n) * SAMPLE_PERIOD_S,
            {
                "SpoolCmd": np.full(n, -50.0),
                ROD_POS.name: 250.0 - 10.0 * np.arange(n),
                "QP": np.full(n, 10.0),
            },
        )
        ok = np.ones(n, dtype=bool)
        flow_series(rec, judged_only(ok), flow)
        lowering_features(rec, ok, flow.lo_mm, flow.hi_mm)
        FlowWindow(flow).push(np.zeros(1), np.nan, -50.0, 250.0, 10.0)
        # The step's inner kernels, called here as ``_push`` calls them, so that they have
        # signatures of their own to be compiled ahead of time with.
        ring_x, ring_q, _, state, fstate = _fresh(1)
        _feature(ring_x, ring_q, state, fstate, -50.0, 250.0, 10.0, True, 0.0, 500.0)
        _judged(np.zeros(1), np.nan, 0.0, 1.0)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> FlowModel:
        return FlowModel.from_dict(d)

    @classmethod
    def check_more(cls, section: dict[str, Any]) -> None:
        for key in ("a_lpm", "b_lpm_per_mm_s", "lo_mm", "hi_mm"):
            check_number(section, key, -1e9, strict=False)
        check_number(section, "scale", 0.0, strict=True)
        check_whole(section, "count_n", 1, MAX_WINDOW_N, "flow.")
        for key in ("oil_lo_c", "oil_hi_c"):  # NaN: none (F judges where J does)
            v = section.get(key, np.nan)
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise ValueError(f"header flow.{key} must be a number, got {str(v)[:40]}")


def _all(feats: Sequence[tuple[np.ndarray, ...]]) -> tuple[np.ndarray, np.ndarray]:
    s = np.concatenate([x[c == 1] for c, x, _ in feats])
    q = np.concatenate([x[c == 1] for c, _, x in feats])
    return s, q


def _folds(
    recs: Sequence[Recording], feats: Sequence[tuple[np.ndarray, ...]]
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per recording, per sample (a, b) of the line fitted without the sample's fold: 60 s
    blocks dealt round-robin to ``FOLDS`` folds over the recordings in order (a fold with
    too few counted samples elsewhere gets the line of them all)."""
    fold_of, start = [], 0
    for r in recs:
        blocks = np.arange(len(r)) // FOLD_BLOCK_N
        fold_of.append((start + blocks) % FOLDS)
        start += int(blocks[-1]) + 1 if len(r) else 0
    lines = np.empty((FOLDS, 2))
    for k in range(FOLDS):
        rest = [(c == 1) & (f != k) for (c, _, _), f in zip(feats, fold_of, strict=True)]
        s = np.concatenate([x[m] for (_, x, _), m in zip(feats, rest, strict=True)])
        q = np.concatenate([x[m] for (_, _, x), m in zip(feats, rest, strict=True)])
        lines[k] = fit_line(s, q) if len(s) >= 2 else fit_line(*_all(feats))
    return [(lines[f, 0], lines[f, 1]) for f in fold_of]
