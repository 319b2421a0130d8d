"""The sim-to-real diagnosis, end to end: prepare, segment, calibrate, test every effect,
decide, and measure how far the gap shrinks.

Verdict rules: see ``decide.py``.  The tolerances are calibrated twice: first from the
nominal values, then again from where the joint refits of the best effects put them, so
that an effect is never credited with what a better calibration alone achieves.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from threadpoolctl import threadpool_limits

from monitor.errors import NoHydraulicDataError
from monitor.gap.data.prepare import Prepared, prepare
from monitor.gap.data.reread import reread, without_arrivals_of
from monitor.gap.data.segments import Segment, make_segments, split, spread
from monitor.gap.fit import calibrate as cal_mod
from monitor.gap.fit import score as S
from monitor.gap.fit import sensorcal
from monitor.gap.fit.candidates import (
    CONFOUNDED,
    KNOBS,
    Candidate,
    Member,
    criterion,
    default_member,
    fit_candidate,
    n_params,
)
from monitor.gap.fit.families import fit_family
from monitor.gap.fit.predict import SENSOR_EFFECTS, SegmentPlant, moves_starts, sense
from monitor.gap.judge import basemis, lagcheck, sensorphysics
from monitor.gap.judge.decide import (
    Decision,
    boot_gain,
    decide,
    explains,
    pair_plan,
    within_noise,
)
from monitor.gap.judge.shrink import resamples
from monitor.gap.judge.suggest import suggest
from monitor.io.recording import Recording
from monitor.sim.effects import Effect
from monitor.sim.machine import MachineParams

#: Seconds of calibration segments the fits simulate per evaluation.
FIT_BUDGET_S = 30.0
#: The fits integrate with this multiple of the configured RK4 step (200 us: 333 us, still
#: 30 steps per 100 Hz sample and a 1 kHz record).  At the stiffest corner of the tolerance
#: bands (volumes and mass -15 %) that departs from the configured step by 0.014 of the
#: pressure sensors' noise variance (500 us: 0.84, 1 ms: several times the noise), so the
#: fits' optimum stays put.
FIT_STEP_FACTOR = 5.0 / 3.0
#: The held-out scores' step, the same multiple: a held-out run of every candidate at the
#: configured step was a third of a diagnosis's CPU, and the departure (0.014 of the noise
#: variance at the stiffest corner) is a small share of the bootstrap spread of any gap the
#: verdict weighs.  The report's whole-recording simulations keep the configured step.
HELDOUT_STEP_FACTOR = FIT_STEP_FACTOR
#: Trust-region iterations of the tolerance calibration (five factors that trade off
#: against each other converge slowly: six iterations left a +-5 % machine 20x the noise).
CAL_ITERATIONS = 15
MIN_SEGMENTS = 3
#: Best single effects refitted together with the tolerances.
REFINE_TOP = 2
#: Local fits of an effect fitted with the tolerance it trades off against (from the best
#: starts, the calibrated and the nominal tolerance among them): friction fitted after a
#: calibration that pushed viscous friction to its bound ended in a worse local minimum.
CONFOUNDED_LOCAL_STARTS = 2
#: The effects that get those two local fits.  For the others the second never ended
#: materially lower on the held-out part (it once ended far worse there) and cost 6-9 %
#: of a diagnosis's CPU (docs/benchmarks.md, "every family's second local fit").
TWO_LOCAL_FITS = ("cylinder_friction",)
#: An effect's fit moved a tolerance off the bound the calibration left it at when it moved
#: it by this share of the band (a friction's fit took viscous friction from +30 % to +19 %
#: or below; a hose's left volumes at +14.3-14.6 % of +15 %, where nothing stood in).
MOVED_OFF = 0.25

Progress = Callable[[str], None]


@dataclass
class Diagnosis:
    """Everything the report needs."""

    prep: Prepared
    segments: list[Segment]
    calibration: list[Segment]
    heldout: list[Segment]
    machine: MachineParams  # tolerance-calibrated
    factors: dict[str, float]
    floor: np.ndarray
    nominal: S.SegmentSums  # held-out, calibrated nominal
    singles: list[Candidate]  # ranked best first
    pairs: list[Candidate]
    sums: dict[str, S.SegmentSums]  # held-out per candidate name
    verdict: str
    also: str | None
    chosen: Candidate | None
    confidence: float
    boot_idx: np.ndarray
    timings_s: dict[str, float] = field(default_factory=dict)
    #: For ``unexplained``: the terms to model next (``suggest.py``); empty otherwise.
    suggestion: list[dict] = field(default_factory=list)
    suggestion_tried: list[dict] = field(default_factory=list)
    # The same, on the smoothed (structured) residual: see ``basemis.py``.
    smooth: dict[str, S.SegmentSums] = field(default_factory=dict)
    smooth_nominal: S.SegmentSums | None = None
    #: A sensor calibration's verdict against the best plant term (``sensorphysics.py``).
    sensor_check: dict | None = None
    #: The best effect, not named because it made a signal clearly worse
    #: (``consistency.py``): the JSON's ``trade_off``.
    traded: dict | None = None
    #: A ``sensor_lag`` verdict checked against the engine's ripple (``lagcheck.py``): the
    #: JSON's ``lag_check``.
    lag_check: dict | None = None
    #: Per candidate name: the calibration absorbed it (``calibration_absorbed``).
    absorbed: dict[str, Absorbed] = field(default_factory=dict)


class _Evaluator:
    """Simulations of a fixed set of segments for (tolerance factors, effects) hypotheses.

    Sensor-only effects reuse the plant runs of the same factors (one cached set), unless a
    sensor calibration error changes the start states.
    """

    def __init__(self, prep: Prepared, segments: Sequence[Segment], machine: MachineParams):
        self.prep, self.segments, self.machine = prep, list(segments), machine
        self.plant = SegmentPlant(prep, segments)
        self._base: tuple[tuple, list] | None = None

    def predict(self, factors: dict[str, float], effects: Sequence[Effect]) -> dict:
        m = cal_mod.apply(self.machine, factors)
        if all(e.name in SENSOR_EFFECTS for e in effects) and not moves_starts(effects):
            key = tuple(sorted(factors.items()))
            if self._base is None or self._base[0] != key:
                self._base = (key, self.plant.traces(m, ()))
            return sense(self.prep, self.segments, self._base[1], effects)
        return sense(self.prep, self.segments, self.plant.traces(m, effects), effects)

    def residual(self, factors: dict[str, float], effects: Sequence[Effect]) -> np.ndarray:
        return S.stacked(self.prep, self.segments, self.predict(factors, effects))

    def sums(self, factors: dict[str, float], effects: Sequence[Effect]) -> S.SegmentSums:
        return S.segment_sums(self.prep, self.segments, self.predict(factors, effects))

    def both_sums(
        self, factors: dict[str, float], effects: Sequence[Effect]
    ) -> tuple[S.SegmentSums, S.SegmentSums]:
        """Sums of the residual and of its smoothed (structured) part, one simulation."""
        pred = self.predict(factors, effects)
        return (
            S.segment_sums(self.prep, self.segments, pred),
            basemis.smoothed_sums(self.prep, self.segments, pred),
        )


class _Readings:
    """Evaluators of the fit and held-out segments, per reading of the recording: as
    prepared (None) and as hypotheses reread it (``reread.py``), built when first asked."""

    def __init__(self, prep: Prepared, fit: tuple, held: tuple):
        self.prep, self._parts = prep, {"fit": fit, "held": held}
        self._made: dict[tuple[str, int], _Evaluator] = {}

    def _get(self, part: str, prep: Prepared | None) -> _Evaluator:
        p = self.prep if prep is None else prep
        key = (part, id(p))  # the evaluator keeps ``p`` alive: its id stays its own
        if key not in self._made:
            self._made[key] = _Evaluator(p, *self._parts[part])
        return self._made[key]

    def fit(self, prep: Prepared | None) -> _Evaluator:
        return self._get("fit", prep)

    def held(self, prep: Prepared | None) -> _Evaluator:
        return self._get("held", prep)


def _score(c: Candidate, sums: S.SegmentSums, floor: np.ndarray, gap0: float, n_eff: float):
    c.heldout_mse = sums.mse()
    c.heldout_gap = S.gap(c.heldout_mse, floor)
    c.heldout_reduction = S.reduction(gap0, c.heldout_gap)
    c.criterion = criterion(c.heldout_gap, floor, n_eff, n_params(c.effects, c.members))


def diagnose(
    rec: Recording,
    machine: MachineParams,
    progress: Progress | None = None,
    effects: Sequence[str] = tuple(KNOBS),
) -> Diagnosis:
    """Diagnose the gap between ``machine``'s simulator and ``rec``."""
    # The fits' linear algebra works on Jacobians of a few columns: BLAS threads gain
    # nothing there, and OpenBLAS's idle threads spin between calls (with two of them, 6 of
    # 16 CPU seconds of a diagnosis went to spinning).
    with threadpool_limits(limits=1, user_api="blas"):
        return _diagnose(rec, machine, progress, effects)


def _diagnose(
    rec: Recording, machine: MachineParams, progress: Progress | None, effects: Sequence[str]
) -> Diagnosis:
    say = progress or (lambda _msg: None)
    clock = time.perf_counter()
    timings: dict[str, float] = {}

    def lap(name: str) -> None:
        timings[name] = time.perf_counter() - clock - sum(timings.values())

    prep = prepare(rec, machine)
    segments = make_segments(prep)
    cal, held = split(segments)
    if len(cal) < MIN_SEGMENTS or len(held) < MIN_SEGMENTS:
        raise NoHydraulicDataError(
            f"{prep.source}: only {len(segments)} usable segments (need {2 * MIN_SEGMENTS}): "
            "too few moves of the boom, or too much missing data"
        )
    fit_segs = spread(cal, FIT_BUDGET_S)
    say(
        f"{len(segments)} segments ({sum(s.quiet for s in segments)} from rest), "
        f"{len(cal)} calibration ({sum(s.duration_s() for s in fit_segs):.0f} s fitted), "
        f"{len(held)} held out; RodPos {'measured' if prep.has_rodpos else 'from flow'}"
    )
    fit_machine = machine.with_changes(step_s=machine.solver.step_s * FIT_STEP_FACTOR)
    held_machine = machine.with_changes(step_s=machine.solver.step_s * HELDOUT_STEP_FACTOR)
    readings = _Readings(prep, (fit_segs, fit_machine), (held, held_machine))
    fit_ev, held_ev = readings.fit(None), readings.held(None)

    def reread_for(effect: Effect) -> tuple[Prepared, sensorcal.Predict] | None:
        other = reread(prep, effect, machine)
        return None if other is None else (other, readings.fit(other).predict)

    tol = cal_mod.knobs()

    # 1. Tolerances first.
    tol_fit = fit_candidate([], fit_ev.residual, {}, tol, [({}, ())], CAL_ITERATIONS)
    # Without RodPos, the arrivals the rod path read through a first QP calibration finds
    # are left out for every candidate, before any is scored (``reread.py``: fairness).
    guess = sensorcal.fit_signal(prep, fit_segs, fit_ev.predict(tol_fit.factors, ()), "QP")
    common = prep if guess is None else without_arrivals_of(prep, guess, machine)
    if common is not prep:
        prep = common
        readings = _Readings(prep, (fit_segs, fit_machine), (held, held_machine))
        fit_ev, held_ev = readings.fit(None), readings.held(None)
    floor = S.noise_floor(prep)
    sums: dict[str, S.SegmentSums] = {}
    smooth: dict[str, S.SegmentSums] = {}
    base = _Baseline(prep, held, held_ev, floor, tol_fit)
    lap("calibrate")
    say("calibrated " + _percent(base.factors))

    member_sums: dict[int, tuple[S.SegmentSums, S.SegmentSums]] = {}

    def scored(c: Candidate) -> Candidate:
        kept = member_sums.pop(id(c), None)
        ev = readings.held(c.prep)  # the recording as ``c`` reads it (same samples)
        both = kept if kept is not None else ev.both_sums(c.factors, c.effects)
        sums[c.name], smooth[c.name] = both
        _score(c, sums[c.name], floor, base.gap0, base.n_eff)
        return c

    def judge(c: Candidate) -> float:
        """A family member's held-out criterion (its sums kept for ``scored``)."""
        member_sums[id(c)] = held_ev.both_sums(c.factors, c.effects)
        _score(c, member_sums[id(c)][0], floor, base.gap0, base.n_eff)
        return c.criterion

    # 2. Every effect on the calibrated machine (with the tolerances it trades off against
    # refitted), then the best few with all the tolerances refitted jointly.
    singles = []
    for i, name in enumerate(effects):
        t0 = time.perf_counter()
        if name == sensorcal.NAME:
            c = sensorcal.fit_candidate(prep, fit_segs, fit_ev.predict, base.factors, reread_for)
            c = scored(c)
        else:
            free = [k for k in tol if k.name in CONFOUNDED.get(name, ())]
            local = CONFOUNDED_LOCAL_STARTS if free and name in TWO_LOCAL_FITS else 1
            c = scored(
                fit_family(
                    name, fit_ev.residual, base.factors, free, local, judge, base.cal.fit_cost
                )
            )
            member_sums.clear()
        singles.append(c)
        say(
            f"[{i + 1}/{len(effects)}] {name}: held-out reduction {c.heldout_reduction:+.2f} "
            f"({time.perf_counter() - t0:.1f} s)"
        )
    singles.sort(key=lambda c: c.criterion)
    lap("candidates")
    if not within_noise(base.nominal, floor):
        for i, c in enumerate(singles[:REFINE_TOP]):
            starts = [(c.factors, c.effects), ({}, c.effects)]
            kept = sums[c.name], smooth[c.name]
            if c.name == sensorcal.NAME:
                own = c.prep if c.prep is not None else prep
                predict = readings.fit(c.prep).predict
                r = sensorcal.refit_with_tolerances(own, fit_segs, predict, c, tol)
            else:
                r = fit_candidate(
                    [c.effects[0].name],
                    fit_ev.residual,
                    base.factors,
                    tol,
                    starts,
                    members=c.members or None,
                )
            r = scored(r)
            say(f"refit {r.name} with tolerances: held-out reduction {r.heldout_reduction:+.2f}")
            if r.criterion < c.criterion:
                singles[i] = r
            else:
                sums[c.name], smooth[c.name] = kept
        # The tolerances again, from where the refits put them (without their effects):
        # if that fits the calibration part better, it is the simulator to beat.
        from_refits = [(base.factors, ())] + [(c.factors, ()) for c in singles[:REFINE_TOP]]
        recal = fit_candidate([], fit_ev.residual, base.factors, tol, from_refits)
        if recal.fit_cost < base.cal.fit_cost:
            base = _Baseline(prep, held, held_ev, floor, recal)
            say("recalibrated " + _percent(base.factors))
            for c in singles:
                _score(c, sums[c.name], floor, base.gap0, base.n_eff)
            singles.sort(key=lambda c: c.criterion)
    lap("refine")
    noise_only = within_noise(base.nominal, floor)

    # 3. Pairs, when the best alone explains the gap but leaves some clearly above the noise.
    idx = resamples(len(held))
    pairs: list[Candidate] = []
    if not noise_only:
        by_name = {c.effects[0].name: c for c in singles}
        for a, b in pair_plan(singles, sums[singles[0].name], floor, base.nominal, idx):
            first, other = by_name[a], by_name[b]
            starts = [(first.factors, (*first.effects, *other.effects))]
            members = [m for x in (first, other) for m in (x.members or member_defaults(x))]
            c = scored(
                fit_candidate([a, b], fit_ev.residual, first.factors, (), starts, members=members)
            )
            pairs.append(c)
            say(f"pair {c.name}: held-out reduction {c.heldout_reduction:+.2f}")
    lap("pairs")

    absorbed = {} if noise_only else calibration_absorbed(singles, base.factors, readings)
    against = {name: a.sums for name, a in absorbed.items()}
    d = decide(
        noise_only,
        singles,
        pairs,
        sums,
        base.nominal,
        idx,
        floor,
        (smooth, base.smooth_nominal),
        against,
    )
    d, lag_checked = _check_lag(
        d, singles, pairs, sums, base, idx, floor, smooth, noise_only, readings, held, against
    )
    if lag_checked is not None:
        say(
            f"sensor lag against the engine's speed ripple: readings {lag_checked['readings']}"
            f"; verdict {lag_checked['verdict_without_check']} -> {d.verdict}"
        )
    lead = checked = None
    if d.verdict in ("unexplained", sensorcal.NAME):
        lead = suggest(
            prep,
            (fit_segs, fit_ev.plant, fit_machine),
            (held, held_ev.plant, held_machine),
            base.factors,
            floor,
            base.gap0,
            base.n_eff,
            held_base=base.pred0,
            # A sensor check compares single terms; the partner of the best is tried only
            # if the verdict ends ``unexplained`` (below).
            pair=d.verdict == "unexplained",
        )
    if d.verdict == sensorcal.NAME and d.chosen is not None and lead is not None:
        # A sensor error moves one signal only: a plant term that explains more of the
        # held-out gap moved the others with it (``sensorphysics.py``).
        checked = sensorphysics.compare(d.chosen, sums[d.chosen.name], lead, idx, floor)
        if checked is not None and not checked.sensor_named:
            say(f"not a sensor error: {checked.term} explains more across the signals")
            d = Decision("unexplained", None, None, checked.plant_share)
    if d.verdict == "unexplained" and lead is not None:
        lead.with_pair()
        say("what to model next: " + (lead.ranked[0]["description"] if lead.ranked else "-"))
    if lead is not None:
        lap("suggest")
    timings["total"] = time.perf_counter() - clock
    return Diagnosis(
        prep,
        segments,
        cal,
        held,
        cal_mod.apply(machine, base.factors),
        base.factors,
        floor,
        base.nominal,
        singles,
        pairs,
        sums,
        d.verdict,
        d.also,
        d.chosen,
        d.confidence,
        idx,
        timings,
        lead.ranked if lead and d.verdict == "unexplained" else [],
        lead.tried if lead else [],
        smooth,
        base.smooth_nominal,
        checked.as_dict() if checked is not None else None,
        _traded(d, singles, S.compared(prep)),
        lag_checked,
        absorbed,
    )


def _check_lag(
    d: Decision,
    singles: list[Candidate],
    pairs: list[Candidate],
    sums: dict[str, S.SegmentSums],
    base: _Baseline,
    idx: np.ndarray,
    floor: np.ndarray,
    smooth: dict[str, S.SegmentSums],
    noise_only: bool,
    readings: _Readings,
    held: Sequence[Segment],
    against: dict[str, tuple[S.SegmentSums, S.SegmentSums]],
) -> tuple[Decision, dict | None]:
    """The verdict after ``lagcheck``: a lagged sensor reports the engine's speed ripple
    late, a slow spool (or any plant effect) leaves it prompt.  Checked when ``sensor_lag``
    is the verdict (prompt readings: decided again without it) or explains the gap alone
    without being the verdict (late readings: it is named, if it explains the gap alone).
    Returns the decision and the JSON's ``lag_check`` (None: not checked)."""
    lag_c = next((c for c in singles if c.effects[0].name == lagcheck.NAME), None)
    if noise_only or lag_c is None:
        return d, None
    structured = (smooth, base.smooth_nominal)
    if d.verdict != lagcheck.NAME and not explains(
        lag_c, boot_gain(base.nominal, sums[lag_c.name], idx, floor)
    ):
        return d, None
    lagged = readings.held(lag_c.prep).predict(lag_c.factors, lag_c.effects)
    chk = lagcheck.check(readings.prep, held, base.pred0, lagged)
    before = d.verdict
    if d.verdict == lagcheck.NAME and chk.prompt:
        rest = [c for c in singles if c is not lag_c]
        plain = [p for p in pairs if all(e.name != lagcheck.NAME for e in p.effects)]
        d = decide(False, rest, plain, sums, base.nominal, idx, floor, structured, against)
    elif d.verdict != lagcheck.NAME and chk.late:
        alone = decide(False, [lag_c], [], sums, base.nominal, idx, floor, structured, against)
        if alone.verdict == lagcheck.NAME:
            d = alone
    return d, {
        **chk.as_dict(),
        "verdict_without_check": before,
        "sensor_named": d.verdict == lagcheck.NAME,
    }


@dataclass
class Absorbed:
    """A calibration that took a tolerance an effect trades off against to its bound, where
    the effect's own fit moved it off: the bound stood in for the effect (``decide.py``)."""

    #: Per tolerance: its factor in the calibration and in the effect's fit.
    tolerances: dict[str, tuple[float, float]]
    #: Held-out whole and smoothed sums of the effect's tolerances without the effect.
    sums: tuple[S.SegmentSums, S.SegmentSums]


def calibration_absorbed(
    singles: Sequence[Candidate], factors: dict[str, float], readings: _Readings
) -> dict[str, Absorbed]:
    """Per physical single effect whose fit moved a confounded tolerance off the bound the
    calibration (``factors``) left it at (by ``MOVED_OFF`` of the band): what its own
    tolerances do without it (one held-out simulation each; none on a machine whose
    calibration is inside its bands)."""
    out = {}
    for c in singles:
        name = c.effects[0].name
        moved = {
            t: (f0, f1)
            for t in CONFOUNDED.get(name, ())
            if cal_mod.bound_side(t, f0 := factors.get(t, 1.0)) != 0
            and abs((f1 := c.factors.get(t, 1.0)) - f0) >= MOVED_OFF * cal_mod.BY_NAME[t].band
        }
        if moved and len(c.effects) == 1:
            out[c.name] = Absorbed(moved, readings.held(c.prep).both_sums(c.factors, ()))
    return out


def _traded(d: Decision, singles: Sequence[Candidate], names: Sequence[str]) -> dict | None:
    """The JSON ``trade_off``: which effect was not named, the signal it made worse."""
    if d.traded is None:
        return None
    name, worse = d.traded
    best = next(c for c in singles if c.effects[0].name == name)
    return {
        "effect": name,
        "member": best.members[0].name if best.members else "default",
        "heldout_reduction": round(float(best.heldout_reduction), 4),
        "signal": names[worse.signal],
        "growth_share": round(worse.growth, 4),
        "bootstrap_share": round(worse.share, 3),
    }


def member_defaults(c: Candidate) -> list[Member]:
    """The default formulation of each of a candidate's effects."""
    return [default_member(e.name) for e in c.effects]


def _percent(factors: dict[str, float]) -> str:
    return ", ".join(f"{k} {100 * (v - 1):+.1f} %" for k, v in factors.items())


class _Baseline:
    """The tolerance-calibrated simulator on the held-out part: what an effect must beat."""

    def __init__(
        self,
        prep: Prepared,
        held: Sequence[Segment],
        held_ev: _Evaluator,
        floor: np.ndarray,
        tol_fit: Candidate,
    ):
        self.cal = tol_fit
        self.factors = tol_fit.factors
        # Kept: the suggestion starts from the same run (``suggest``'s ``held_base``).
        self.pred0 = pred0 = held_ev.predict(self.factors, ())
        self.nominal = S.segment_sums(prep, held, pred0)
        self.smooth_nominal = basemis.smoothed_sums(prep, held, pred0)
        self.gap0 = S.gap(self.nominal.mse(), floor)
        self.n_eff = S.effective_n(prep, held, pred0)
