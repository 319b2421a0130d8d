"""The ``sensor_calibration`` candidate: gain and offset of one measured signal.

A sensor error changes what one transducer reads, not the physics: the plant the
calibrated simulator already ran is the same, so the candidate needs no new plant run.  For
each measured signal in turn, the reading ``gain x simulated + offset`` is fitted to the
recording by linear least squares on the calibration part; the signal whose fit removes the
most of the (normalised) calibration residual is the candidate.  It is then scored on the
held-out part like every other candidate.  Because it can only move one signal, it cannot
explain a gap that a physical effect spreads over several signals consistently: there a
physical effect removes more, and wins the ranking.

RodPos is compared through the rod velocity, which an offset does not change: its gain is
fitted, its offset is left at 0 (not observable from the velocity).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from monitor.gap import score as S
from monitor.gap.candidates import Candidate
from monitor.gap.fit import Knob, fit
from monitor.gap.predict import moves_starts
from monitor.gap.prepare import ROD_VEL, Prepared, rod_velocity
from monitor.gap.segments import Segment
from monitor.sim.effects import CATALOGUE, SENSOR_CAL_SIGNALS, Effect

NAME = "sensor_calibration"
Predict = Callable[[dict[str, float], tuple[Effect, ...]], dict[str, np.ndarray]]


def compared_column(signal: str) -> str:
    """The column of ``Prepared.meas`` on which a calibration error of ``signal`` shows."""
    return ROD_VEL if signal == "RodPos" else signal


def report_keys(effect: Effect) -> dict[str, tuple[float, str]]:
    """The contract's signal-named parameters (``PA_gain``, ``QP_offset_lpm``): value and
    unit of each."""
    signal = effect.labels["signal"]
    sig = SENSOR_CAL_SIGNALS[signal]
    return {
        f"{signal}_gain": (effect.params["gain"], "-"),
        f"{signal}_offset_{sig.key_unit}": (effect.params["offset"], sig.unit),
    }


def _rows(segments: Sequence[Segment]) -> np.ndarray:
    return np.concatenate([np.arange(s.score_from, s.stop) for s in segments])


def _base(prep: Prepared, segments: Sequence[Segment], col: str) -> np.ndarray:
    """What a prediction of ``col`` holds besides the sensor's own reading: 0, except for the
    rod velocity, which ``predict.sense`` builds as measured + simulated - measured filtered
    within the segment (so a gain scales only the simulated part)."""
    out = np.zeros(len(prep))
    if col == ROD_VEL:
        for seg in segments:
            rows = slice(seg.start, seg.stop + 1)
            out[rows] = prep.meas[ROD_VEL][rows] - rod_velocity(prep.rod_mm[rows])
    return out


def _recalibrated(
    prep: Prepared,
    segments: Sequence[Segment],
    pred: dict[str, np.ndarray],
    old: Effect,
    new: Effect,
) -> dict[str, np.ndarray]:
    """``pred`` (made with ``old``) with ``new``'s gain and offset on the same signal instead:
    the sensor model only, the plant runs (started through ``old``) kept."""
    col = compared_column(old.labels["signal"])
    base = _base(prep, segments, col)
    raw = (pred[col] - base - old.params["offset"]) / old.params["gain"]
    return {**pred, col: base + new.params["gain"] * raw + new.params["offset"]}


def _linear(x: np.ndarray, y: np.ndarray, with_offset: bool) -> tuple[float, float]:
    """Least-squares ``y ~ gain x + offset`` (offset 0 when not fitted)."""
    if with_offset:
        a = np.column_stack([x, np.ones_like(x)])
        (gain, offset), *_ = np.linalg.lstsq(a, y, rcond=None)
        return float(gain), float(offset)
    den = float(x @ x)
    return (float(x @ y) / den if den > 0 else 1.0), 0.0


def fit_signal(
    prep: Prepared,
    segments: Sequence[Segment],
    pred: dict[str, np.ndarray],
    signal: str,
    applied: Effect | None = None,
) -> tuple[Effect, float] | None:
    """The best gain and offset of ``signal`` (within the catalogue's ranges) for a
    prediction ``pred`` made with ``applied`` (a sensor calibration of the same signal, or
    None), and the drop of the summed squared normalised residual against no calibration
    error; None if the signal is not compared."""
    col = compared_column(signal)
    if col not in pred:
        return None
    rows = _rows(segments)
    base = _base(prep, segments, col)[rows]
    x = pred[col][rows] - base
    if applied is not None:
        x = (x - applied.params["offset"]) / applied.params["gain"]
    y = prep.meas[col][rows] - base
    ok = np.isfinite(x) & np.isfinite(y)
    if ok.sum() < 10:
        return None
    x, y = x[ok], y[ok]
    gain, offset = _linear(x, y, with_offset=signal != "RodPos")
    g_spec, o_spec = CATALOGUE[NAME].param("gain"), SENSOR_CAL_SIGNALS[signal]
    gain = min(max(gain, g_spec.low), g_spec.high)
    offset = min(max(offset, -o_spec.max_offset), o_spec.max_offset)
    drop = float(np.sum((x - y) ** 2) - np.sum((gain * x + offset - y) ** 2)) / prep.scale[col] ** 2
    return Effect.make(NAME, signal=signal, gain=gain, offset=offset), drop


def best_signal(prep: Prepared, segments: Sequence[Segment], pred: dict[str, np.ndarray]) -> Effect:
    """The signal whose gain and offset remove the most of the calibration residual."""
    fits = [fit_signal(prep, segments, pred, s) for s in SENSOR_CAL_SIGNALS]
    fitted = [f for f in fits if f is not None]
    return max(fitted, key=lambda f: f[1])[0]


#: Refits of gain and offset from plant runs started from the corrected state (a pressure
#: or RodPos error also sets the start states wrong; the fixed point is reached in two).
START_REFITS = 2


def _refined(
    prep: Prepared,
    segments: Sequence[Segment],
    predict: Predict,
    factors: dict[str, float],
    effect: Effect,
    refits: int = START_REFITS,
) -> tuple[Effect, dict[str, np.ndarray]]:
    """``effect``'s gain and offset refitted on plant runs started from the state the
    recording shows once read through the inverse of ``effect``; with the prediction."""
    pred = predict(factors, (effect,))
    if not moves_starts((effect,)):
        return effect, pred
    for _ in range(refits):
        found = fit_signal(prep, segments, pred, effect.labels["signal"], applied=effect)
        if found is None:
            break
        effect = found[0]
        pred = predict(factors, (effect,))
    return effect, pred


def fit_candidate(
    prep: Prepared,
    segments: Sequence[Segment],
    predict: Predict,
    factors: dict[str, float],
) -> Candidate:
    """The candidate on the calibrated machine (``factors``): the signal is chosen on the
    plant runs of the calibrated nominal simulator (a few linear fits); a signal that sets
    the start states gets START_REFITS plant runs more."""
    effect = best_signal(prep, segments, predict(factors, ()))
    effect, pred = _refined(prep, segments, predict, factors, effect)
    resid = S.stacked(prep, segments, pred)
    return Candidate((effect,), dict(factors), float(np.mean(resid**2)))


def refit_with_tolerances(
    prep: Prepared,
    segments: Sequence[Segment],
    predict: Predict,
    first: Candidate,
    tolerances: Sequence[Knob],
) -> Candidate:
    """The tolerances fitted jointly with the candidate's signal (gain and offset solved in
    closed form at every step: the first calibration may have bent the machine towards
    the sensor error)."""
    current = first.effects[0]

    def residual(values: dict[str, float]) -> np.ndarray:
        nonlocal current
        # One plant run per evaluation, started through the last gain and offset; the
        # closed-form refit then moves them only a little, on the sensor model alone.
        pred = predict({**first.factors, **values}, (current,))
        found = fit_signal(prep, segments, pred, current.labels["signal"], applied=current)
        if found is not None:
            pred = _recalibrated(prep, segments, pred, current, found[0])
            current = found[0]
        return S.stacked(prep, segments, pred)

    starts = [{k.name: first.factors.get(k.name, 1.0) for k in tolerances}]
    starts.append({k.name: 1.0 for k in tolerances})
    result = fit(residual, tolerances, starts)
    factors = {**first.factors, **result.values}
    effect, pred = _refined(prep, segments, predict, factors, current)
    cost = float(np.mean(S.stacked(prep, segments, pred) ** 2))
    return Candidate((effect,), factors, cost)
