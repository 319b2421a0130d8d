"""The ``sensor_calibration`` candidate: gain and offset of one measured signal.

A sensor error changes what one transducer reads, not the physics, so the plant the
calibrated simulator already ran serves: for each measured signal in turn the reading
``gain x simulated + offset`` is fitted to the recording by linear least squares on the
calibration part.  Two things a reading error does reach beyond its own signal are
followed with a few plant runs more: a pressure or RodPos reading also sets the segments'
start states (they are re-run from the start read through the inverse calibration), and a
RodPos offset shows only there (the compared rod velocity has no offset), so it is searched.
Without RodPos a QP error reaches the rod path too (integrated from QP, anchored on the
stalls a QP offset hides): the QP hypothesis is fitted again on the recording reread
through it (``reread.py``), the same readings and samples, so its cost stays comparable.
The signal whose hypothesis fits the calibration part best is the candidate, scored on the
held-out part like every other.

What a sensor error cannot do tells it from physics: it changes one signal, so it cannot
explain a gap that a physical effect spreads consistently over several (there the physical
effect wins the ranking); and a flow meter or stroke sensor error breaks the kinematics
between pump flow and rod speed, which leakage or friction keep (``kinematic_mismatch``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from scipy.optimize import minimize_scalar

from monitor.gap.data.prepare import ROD_VEL, Prepared
from monitor.gap.data.segments import Segment
from monitor.gap.fit import score as S
from monitor.gap.fit.candidates import Candidate
from monitor.gap.fit.kinematics import (
    kinematic_ratio,
    kinematically_consistent,
    scored_rows,
    velocity_base,
)
from monitor.gap.fit.predict import moves_starts
from monitor.gap.fit.solve import Knob, fit
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
    base = velocity_base(prep, segments, col)
    raw = (pred[col] - base - _shown_offset(old)) / old.params["gain"]
    out = base + new.params["gain"] * raw + _shown_offset(new)
    return {**pred, col: out if col == ROD_VEL else prep.reading(col, out)}  # as predict.sense


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
) -> Effect | None:
    """The best gain and offset of ``signal`` (within the catalogue's ranges) for a
    prediction ``pred`` made with ``applied`` (a sensor calibration of the same signal, or
    None); None if the signal is not compared.

    Rows where the measured signal sits at the sensor's zero are left out: a negative
    offset reads 0 there (the sensor clips), not the offset (``Prepared.off_zero``).
    A RodPos gain is the ratio of measured to simulated rod speed per pump flow where that
    is known (extension, clear of the stops): fitted to the rod velocity's residual, it came
    out low when the reading clips at the top of its range, and it would soak up physics
    through the start states."""
    col = compared_column(signal)
    if col not in pred:
        return None
    rows = scored_rows(segments)
    base = velocity_base(prep, segments, col)[rows]
    x = pred[col][rows] - base
    if applied is not None:
        x = (x - _shown_offset(applied)) / applied.params["gain"]
    y = prep.meas[col][rows] - base
    ok = np.isfinite(x) & np.isfinite(y)
    if signal != "RodPos":
        ok &= prep.off_zero(col, y)
    if signal in LOAD_SIGNALS and (ok & _steady(x) & _steady(y)).sum() >= STEADY_MIN_ROWS:
        ok &= _steady(x) & _steady(y)
    if ok.sum() < 10:
        return None
    if signal == "RodPos":  # the velocity has no offset: keep the one the plant ran with
        ratio = kinematic_ratio(prep, rows, pred["QP"][rows], x, prep.meas["QP"][rows], y)
        gain = ratio if ratio is not None else _linear(x[ok], y[ok], with_offset=False)[0]
        offset = _offset(applied)
    else:
        gain, offset = _linear(x[ok], y[ok], with_offset=True)
    g_spec, o_spec = CATALOGUE[NAME].param("gain"), SENSOR_CAL_SIGNALS[signal]
    gain = min(max(gain, g_spec.low), g_spec.high)
    offset = min(max(offset, -o_spec.max_offset), o_spec.max_offset)
    return Effect.make(NAME, signal=signal, gain=gain, offset=offset)


#: A reading error shows where the pressure holds: within this (bar) over 0.1 s each side.
#: The transients carry the base's timing (the third plant's PA read 20 ms late), which
#: drew a PA gain of 1.063 down to 1.008-1.017 when fitted on every row.
STEADY_BAR, _STEADY_LAG, STEADY_MIN_ROWS = 1.0, 10, 200


def _steady(v: np.ndarray) -> np.ndarray:
    out = np.ones(len(v), dtype=bool)
    d = np.abs(v[_STEADY_LAG:] - v[:-_STEADY_LAG]) < STEADY_BAR
    out[_STEADY_LAG:] &= d
    out[:-_STEADY_LAG] &= d
    return out


def _offset(effect: Effect | None) -> float:
    return 0.0 if effect is None else effect.params["offset"]


def _shown_offset(effect: Effect) -> float:
    """The offset in the compared column: none for RodPos (compared as a velocity)."""
    return 0.0 if effect.labels["signal"] == "RodPos" else effect.params["offset"]


#: RodPos offsets tried first (mm): the objective is rough (a rod started a few mm off an
#: end stop it rests on, or snapped onto it), so a grid comes before the local search.
ROD_OFFSET_GRID_MM = (-40.0, -20.0, -10.0, -5.0, -2.0, 0.0, 2.0, 5.0, 10.0, 20.0, 40.0)
#: Share of the calibration cost at zero offset a RodPos offset must remove to be kept.
ROD_OFFSET_MIN_GAIN = 0.2


def _rod_offset(
    prep: Prepared,
    segments: Sequence[Segment],
    predict: Predict,
    factors: dict[str, float],
    gain: float,
) -> Effect:
    """The RodPos offset, seen only through the start states (which rod starts rest on an
    end stop, how far the chambers are filled): one plant run per offset tried, the gain
    refitted in closed form on each."""

    def cost(offset: float) -> tuple[float, Effect]:
        effect = Effect.make(NAME, signal="RodPos", gain=gain, offset=offset)
        pred = predict(factors, (effect,))
        found = fit_signal(prep, segments, pred, "RodPos", applied=effect)
        if found is not None:
            pred = _recalibrated(prep, segments, pred, effect, found)
            effect = found
        return float(np.mean(S.stacked(prep, segments, pred) ** 2)), effect

    at_stop = top_stop_offset(prep, gain)
    # Beyond what the catalogue names it is not this sensor's stop (a QP gain read as a
    # RodPos gain of 1.12 put the outsider's top stop at -62 mm): searched instead.
    if at_stop is not None and abs(at_stop) <= SENSOR_CAL_SIGNALS["RodPos"].max_offset:
        # Read where the rod rests on its top stop: below that offset the same rods start on
        # the stops, so the starts cannot tell (a -25 mm offset was searched at -35).
        done = cost(at_stop)
        return done[1] if done[0] <= (1.0 - ROD_OFFSET_MIN_GAIN) * cost(0.0)[0] else cost(0.0)[1]
    # A sensor that clips at zero shows a negative offset only at the top stop, which the
    # rod did not rest on: searched among the offsets its bottom reading would show.  (Free
    # to go negative, the starts it moves took up 73 % of a pump leak's gap at -28 mm.)
    grid_mm = [o for o in ROD_OFFSET_GRID_MM if o >= 0.0 or not prep.rod_clips]
    tried = {o: cost(o) for o in grid_mm}
    grid = sorted(tried)
    i = min(range(len(grid)), key=lambda k: tried[grid[k]][0])
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    res = minimize_scalar(
        lambda o: cost(o)[0],
        bounds=(lo, hi),
        method="bounded",
        options={"xatol": 0.5, "maxiter": 12},
    )
    best = min(cost(float(res.x)), tried[grid[i]], key=lambda c: c[0])
    # Without end-stop events in the fit segments the objective is flat in the offset, and
    # a drifting offset starts held-out rods off the stops they rest on (a RodPos gain of
    # 0.95 got 10 mm and was judged unexplained): an offset must earn its place.
    if best[0] > (1.0 - ROD_OFFSET_MIN_GAIN) * tried[0.0][0]:
        return tried[0.0][1]
    return best[1]


#: A rod stalled on its top stop: pushed out (SpoolCmd above this, %) at under this speed
#: (mm/s), within this of its highest reading (mm), for at least this many samples.
_STOP_SPOOL_PCT, _STOP_SPEED_MM_S, _STOP_BAND_MM, _STOP_MIN_ROWS = 10.0, 5.0, 2.0, 20


def top_stop_offset(prep: Prepared, gain: float) -> float | None:
    """The RodPos offset the top end stop shows: the reading where the rod stalls at its
    highest, pushed out, is ``gain x stroke + offset``; None when it never rests there."""
    if ROD_VEL not in prep.meas:
        return None
    rod = prep.rod_mm
    top = float(np.nanmax(rod))
    stalled = (
        (prep.cmd["SpoolCmd"] > _STOP_SPOOL_PCT)
        & (np.abs(prep.meas[ROD_VEL]) < _STOP_SPEED_MM_S)
        & (rod > top - _STOP_BAND_MM)
    )
    if stalled.sum() < _STOP_MIN_ROWS:
        return None
    return float(np.median(rod[stalled])) - gain * prep.stroke_mm


#: The recording reread through a hypothesis, with the predictor of its segments
#: (``reread.py``); None where the hypothesis reads the recording as prepared.
Reread = Callable[[Effect], tuple[Prepared, Predict] | None]
#: Rereadings of a hypothesis, each from the gain and offset fitted on the last: the first
#: finds the stalls the offset hid, after which the fit moves the offset by hundredths of a
#: L/min, far inside ``rodflow.STALL_FLOW_LPM``.
REREADS = 1


def _hypotheses(
    prep: Prepared,
    segments: Sequence[Segment],
    predict: Predict,
    factors: dict[str, float],
    reread: Reread | None = None,
) -> list[tuple[float, Effect, Prepared | None]]:
    """(calibration cost, effect, the recording as the effect reads it or None) per signal:
    gain and offset in closed form on the calibrated nominal's plant runs, refitted from
    corrected start states where the signal sets them (a RodPos offset is searched: the
    velocity does not show it), and on the recording reread through the effect where it
    changes how the recording is read (``reread``)."""
    base = predict(factors, ())
    out = []
    for signal in SENSOR_CAL_SIGNALS:
        effect = fit_signal(prep, segments, base, signal)
        if effect is None:
            continue
        if signal == "RodPos":
            effect = _rod_offset(prep, segments, predict, factors, effect.params["gain"])
        effect, pred = _refined(prep, segments, predict, factors, effect)
        own: Prepared | None = None
        for _ in range(REREADS if reread is not None else 0):
            reading = reread(effect) if reread is not None else None
            found = _fitted_on(reading, segments, factors, signal) if reading else None
            if reading is None or found is None:
                break
            own, (effect, pred) = reading[0], found
        if not kinematically_consistent(prep, segments, base, effect):
            continue
        # The same readings and samples either way (``reread.py``): costs comparable.
        out.append((float(np.mean(S.stacked(prep, segments, pred) ** 2)), effect, own))
    return out


#: The chamber pressures, whose transients carry the base's timing (``_steady``).
LOAD_SIGNALS = ("PA", "PB")


def _fitted_on(
    reading: tuple[Prepared, Predict],
    segments: Sequence[Segment],
    factors: dict[str, float],
    signal: str,
) -> tuple[Effect, dict[str, np.ndarray]] | None:
    """``signal``'s gain and offset fitted on a reread recording, with the prediction."""
    prep, predict = reading
    effect = fit_signal(prep, segments, predict(factors, ()), signal)
    return None if effect is None else _refined(prep, segments, predict, factors, effect)


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
        effect = found
        pred = predict(factors, (effect,))
    return effect, pred


def fit_candidate(
    prep: Prepared,
    segments: Sequence[Segment],
    predict: Predict,
    factors: dict[str, float],
    reread: Reread | None = None,
) -> Candidate:
    """The candidate on the calibrated machine (``factors``): the signal whose hypothesis
    fits the calibration part best (a few linear fits and a few dozen plant runs of the
    fit segments, for the signals that set the start states or reread the recording)."""
    hyps = _hypotheses(prep, segments, predict, factors, reread)
    cost, effect, own = min(hyps, key=lambda h: h[0])
    return Candidate((effect,), dict(factors), cost, prep=own)


def refit_with_tolerances(
    prep: Prepared,
    segments: Sequence[Segment],
    predict: Predict,
    first: Candidate,
    tolerances: Sequence[Knob],
) -> Candidate:
    """The tolerances fitted jointly with the candidate's signal (gain and offset solved in
    closed form at every step: the first calibration may have bent the machine towards
    the sensor error).  ``prep`` and ``predict``: the recording as ``first`` reads it."""
    current = first.effects[0]

    def residual(values: dict[str, float]) -> np.ndarray:
        nonlocal current
        # One plant run per evaluation, started through the last gain and offset; the
        # closed-form refit then moves them only a little, on the sensor model alone.
        pred = predict({**first.factors, **values}, (current,))
        found = fit_signal(prep, segments, pred, current.labels["signal"], applied=current)
        if found is not None:
            pred = _recalibrated(prep, segments, pred, current, found)
            current = found
        return S.stacked(prep, segments, pred)

    starts = [{k.name: first.factors.get(k.name, 1.0) for k in tolerances}]
    starts.append({k.name: 1.0 for k in tolerances})
    result = fit(residual, tolerances, starts)
    factors = {**first.factors, **result.values}
    effect, pred = _refined(prep, segments, predict, factors, current)
    cost = float(np.mean(S.stacked(prep, segments, pred) ** 2))
    return Candidate((effect,), factors, cost, prep=first.prep)
