"""A lead for ``unexplained``: which term, added to the simulator, explains the held-out gap.

When no catalogue effect explains the gap, every term of a small library of physical
shapes (``terms.py``: leakage between named volumes in dp, sqrt(dp) and dp^2, rod forces in
velocity, sign(velocity), position and a periodic load, pump and valve settings;
``sensorterms.py``: a sensor's gain, offset or delay) is added in turn to the
tolerance-calibrated simulator, its one or two coefficients fitted on the calibration
segments, and scored on the held-out segments like the effects (same held-out reduction,
same penalised criterion).  The answer is sparse: the best term, and a second one only
when the pair removes clearly more than the best alone (the rules a second effect meets).

Cost: every plant term is screened with one Gauss-Newton step from the calibrated
simulator (one finite-difference run of the fit segments per coefficient); the best few
get one more step and a run of their own, the best three a held-out run.  The periodic
load's frequency is one of a few lines of the calibration residual's spectrum, so only its
amplitude and phase are fitted (two linear coefficients).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from monitor.gap.data.prepare import Prepared
from monitor.gap.data.segments import Segment
from monitor.gap.fit import calibrate as cal_mod
from monitor.gap.fit import score as S
from monitor.gap.fit.candidates import criterion
from monitor.gap.fit.predict import SegmentPlant, sense
from monitor.gap.fit.sensorterms import SensorTerm, fit_sensor_terms
from monitor.gap.fit.terms import PlantTerm, describe, library, periodic
from monitor.gap.judge.decide import PAIR_GAIN, PAIR_MATERIAL
from monitor.gap.judge.periodic import periodic_frequencies_hz
from monitor.sim.machine import MachineParams

#: Plant terms refined (a second Gauss-Newton step and a run of their own) after screening.
REFINE = 3
#: Terms scored on the held-out part (the best by calibration cost; sensor terms extra).
SCORED = 3
#: Runners-up tried as the best term's partner.
PAIR_POOL = 2
#: A term is suggested only when it removes at least this share of the held-out gap (one
#: that makes the held-out part worse is no lead).
SUGGEST_MIN = 0.2

Pred = dict[str, np.ndarray]


@dataclass(eq=False)
class Fitted:
    """A term (or a pair) with fitted coefficients and its scores."""

    terms: tuple[PlantTerm | SensorTerm, ...]
    coefs: tuple[np.ndarray, ...]  # per plant term (empty for a sensor term)
    fit_cost: float
    factors: dict[str, float] | None = None  # tolerances refitted with the term (else: the
    # calibration's)
    heldout_gap: float = math.inf
    heldout_reduction: float = 0.0
    criterion: float = math.inf
    sums: S.SegmentSums | None = None  # held-out, once scored

    @property
    def n_coefs(self) -> int:
        return sum(len(c) if len(c) else 1 for c in self.coefs)


@dataclass
class Suggestions:
    ranked: list[dict]  # the contract's ``suggestion`` (one or two entries)
    tried: list[dict] = field(default_factory=list)  # every term scored on the held-out part
    singles: list[Fitted] = field(default_factory=list)  # scored single terms, best first
    # The best term's partner, not yet tried (``suggest(..., pair=False)``): the ranking
    # with it, computed on demand by ``with_pair``.
    pending: Callable[[], list[dict]] | None = None

    def with_pair(self) -> Suggestions:
        """The ranking with the best term's partner tried, if that was left for later (a
        sensor check needs the singles only; the pair counts only when no sensor is named)."""
        if self.pending is not None:
            self.ranked, self.pending = self.pending(), None
        return self


Terms = Sequence[tuple[PlantTerm | SensorTerm, np.ndarray]]


class _Runs:
    """Simulated readings of a set of segments for a set of terms on the nominal machine
    ``m0`` with tolerance factors (the calibration's unless given)."""

    def __init__(
        self,
        prep: Prepared,
        segments: Sequence[Segment],
        plant: SegmentPlant,
        m0: MachineParams,
        factors: dict[str, float],
        base: Pred | None = None,
    ):
        """``base``: the readings of the calibrated machine without a term, when the caller
        has simulated them already (the same run: not repeated)."""
        self.prep, self.segments, self.plant, self.m0 = prep, list(segments), plant, m0
        self.machine = cal_mod.apply(m0, factors)
        if base is None:
            base = sense(prep, self.segments, plant.traces(self.machine, ()), ())
        self.base = base

    def pred(self, terms: Terms, factors: dict[str, float] | None = None) -> Pred:
        m = self.machine if factors is None else cal_mod.apply(self.m0, factors)
        corr: dict[str, float] = {}
        plant_terms = [(t, c) for t, c in terms if isinstance(t, PlantTerm)]
        for t, c in plant_terms:
            m, more = t.apply(m, c)
            corr.update(more)
        if plant_terms or factors is not None:
            pred = sense(self.prep, self.segments, self.plant.traces(m, (), corr), ())
        else:
            pred = self.base
        for term, _ in terms:
            if isinstance(term, SensorTerm):
                pred = term.apply(self.prep, self.segments, pred)
        return pred

    def residual(self, terms: Terms, factors: dict[str, float] | None = None) -> np.ndarray:
        return S.stacked(self.prep, self.segments, self.pred(terms, factors))


def _gn_step(
    runs: _Runs,
    fixed: Terms,
    term: PlantTerm,
    c: np.ndarray,
    r: np.ndarray,
    factors: dict[str, float] | None = None,
) -> tuple[np.ndarray, float]:
    """One Gauss-Newton step of ``term``'s coefficients from ``c`` (residual ``r`` there):
    forward differences, bounded; returns the new coefficients and the cost the linear
    model predicts for them."""
    cols = []
    for i, h in enumerate(term.steps):
        ci = c.copy()
        ci[i] = ci[i] + h if ci[i] + h <= term.high[i] else ci[i] - h
        cols.append((runs.residual([*fixed, (term, ci)], factors) - r) / (ci[i] - c[i]))
    jac = np.column_stack(cols)
    dc, *_ = np.linalg.lstsq(jac, -r, rcond=None)
    new = np.clip(c + dc, term.low, term.high)
    return new, float(np.mean((r + jac @ (new - c)) ** 2))


def _plant(f: Fitted) -> PlantTerm:
    """The term of a single plant-term fit (what ``_fit_plant`` returns)."""
    term = f.terms[0]
    if not isinstance(term, PlantTerm):
        raise TypeError(f"not a plant term: {term!r}")
    return term


def _fit_plant(runs: _Runs, term: PlantTerm, r0: np.ndarray, steps: int) -> Fitted:
    """``term``'s coefficients from zero by ``steps`` Gauss-Newton steps; with one step, the
    cost is the linear model's prediction (no run at the new point)."""
    c, r = np.zeros(len(term.steps)), r0
    cost0 = float(np.mean(r0**2))
    new, predicted = _gn_step(runs, (), term, c, r)
    if steps == 1:
        return Fitted((term,), (new,), min(predicted, cost0))
    best = Fitted((term,), (c,), cost0)
    for k in range(steps):
        r_new = runs.residual([(term, new)])
        cost = float(np.mean(r_new**2))
        if cost >= best.fit_cost:
            break
        best = Fitted((term,), (new,), cost)
        if k + 1 < steps:
            new, _ = _gn_step(runs, (), term, new, r_new)
    return best


#: Finite-difference step of a tolerance factor in the joint refit.
_FACTOR_STEP = 0.02
#: Gauss-Newton steps of the joint refit.
JOINT_STEPS = 2


def _refit_with_tolerances(runs: _Runs, f: Fitted, factors: dict[str, float]) -> Fitted:
    """The best term's coefficients and every tolerance factor fitted jointly (a few
    Gauss-Newton steps from the better of the calibrated and the nominal factors): the
    calibration, made without the term, may have bent the machine towards it (an A->tank
    leak takes mass, gravity load and volumes to their bounds)."""
    term = f.terms[0]
    tols = [t for t in cal_mod.TOLERANCES if t.name in factors or not t.added]
    assert isinstance(term, PlantTerm)
    n = len(term.steps)
    low = np.array([*term.low, *(t.knob().low for t in tols)])
    high = np.array([*term.high, *(t.knob().high for t in tols)])
    steps = np.array([*term.steps, *([_FACTOR_STEP] * len(tols))])

    def fac(x: np.ndarray) -> dict[str, float]:
        return {t.name: float(v) for t, v in zip(tols, x[n:], strict=True)}

    def residual(x: np.ndarray) -> np.ndarray:
        return runs.residual([(term, x[:n])], fac(x))

    starts = [
        np.array([*f.coefs[0], *(factors.get(t.name, 1.0) for t in tols)]),
        np.array([*f.coefs[0], *([1.0] * len(tols))]),
    ]
    tried = [(float(np.mean(r**2)), x, r) for x in starts for r in [residual(x)]]
    cost, x, r = min(tried, key=lambda c: c[0])
    for _ in range(JOINT_STEPS):
        cols = []
        for i, h in enumerate(steps):
            xi = x.copy()
            xi[i] = xi[i] + h if xi[i] + h <= high[i] else xi[i] - h
            cols.append((residual(xi) - r) / (xi[i] - x[i]))
        dx, *_ = np.linalg.lstsq(np.column_stack(cols), -r, rcond=None)
        x_new = np.clip(x + dx, low, high)
        r_new = residual(x_new)
        cost_new = float(np.mean(r_new**2))
        if cost_new >= cost:
            break
        cost, x, r = cost_new, x_new, r_new
    return Fitted((term,), (x[:n],), cost, fac(x))


def _sensor_fitted(runs: _Runs, t: SensorTerm) -> Fitted:
    return Fitted((t,), (np.zeros(0),), float(np.mean(runs.residual([(t, np.zeros(0))]) ** 2)))


def _pairs(f: Fitted) -> list[tuple[PlantTerm | SensorTerm, np.ndarray]]:
    return list(zip(f.terms, f.coefs, strict=True))


def suggest(
    prep: Prepared,
    fit: tuple[Sequence[Segment], SegmentPlant, MachineParams],
    held: tuple[Sequence[Segment], SegmentPlant, MachineParams],
    factors: dict[str, float],
    floor: np.ndarray,
    gap0: float,
    n_eff: float,
    held_base: Pred | None = None,
    pair: bool = True,
) -> Suggestions:
    """Ranked correction terms for an ``unexplained`` gap.  ``fit`` and ``held``: the
    segments, their plant and the nominal machine (at the fits' step and the configured
    step); ``factors`` the calibrated tolerances; ``gap0`` the calibrated simulator's
    held-out gap and ``n_eff`` its effective sample size (as for the effects);
    ``held_base`` the held-out readings of the calibrated machine, if already simulated;
    ``pair`` False leaves the best term's partner for ``Suggestions.with_pair``."""
    fit_runs, held_runs = _Runs(prep, *fit, factors), _Runs(prep, *held, factors, held_base)
    r0 = fit_runs.residual(())
    lines = periodic_frequencies_hz(prep, fit[0], fit_runs.base)
    plant_terms = [*library(), *(periodic(2 * math.pi * f) for f in lines)]

    screened = sorted(
        (_fit_plant(fit_runs, t, r0, 1) for t in plant_terms), key=lambda f: f.fit_cost
    )
    refined = [_fit_plant(fit_runs, _plant(f), r0, 2) for f in screened[:REFINE]]
    refined.sort(key=lambda f: f.fit_cost)
    sensors = sorted(
        (_sensor_fitted(fit_runs, t) for t in fit_sensor_terms(prep, fit[0], fit_runs.base)),
        key=lambda f: f.fit_cost,
    )

    scored = _Scorer(prep, held_runs, floor, gap0, n_eff)
    # The periodic term is always scored: its frequency is the data's own line, and a load
    # the calibration half absorbed can rank it low on the calibration part.
    per: list[Fitted] = []
    if not _periodic_in(refined[:SCORED]):
        per = _periodic_in(refined[SCORED:])[:1]
        if not per and _periodic_in(screened[REFINE:]):
            per = [_fit_plant(fit_runs, _plant(_periodic_in(screened[REFINE:])[0]), r0, 2)]
    singles = [scored(f) for f in [*refined[:SCORED], *per[:1], *sensors[:1]]]
    singles.sort(key=lambda f: f.criterion)
    if isinstance(singles[0].terms[0], PlantTerm):
        joint = _refit_with_tolerances(fit_runs, singles[0], factors)
        if joint.fit_cost < singles[0].fit_cost and scored(joint).criterion < singles[0].criterion:
            singles[0] = joint
    best = singles[0]
    tried = [_entry(f, f.terms[0], f.coefs[0], f.heldout_reduction) for f in singles]
    if best.heldout_reduction < SUGGEST_MIN:
        return Suggestions([], tried, singles)
    paired = partial(_with_partner, fit_runs, singles, r0, scored)
    if not pair:
        return Suggestions(_alone(best), tried, singles, paired)
    return Suggestions(paired(), tried, singles)


@dataclass(frozen=True)
class _Scorer:
    """Scores a fitted term (or pair) on the held-out part, like the effects."""

    prep: Prepared
    held_runs: _Runs
    floor: np.ndarray
    gap0: float
    n_eff: float

    def __call__(self, f: Fitted) -> Fitted:
        runs = self.held_runs
        sums = S.segment_sums(self.prep, runs.segments, runs.pred(_pairs(f), f.factors))
        f.heldout_gap = S.gap(sums.mse(), self.floor)
        f.heldout_reduction = S.reduction(self.gap0, f.heldout_gap)
        f.criterion = criterion(f.heldout_gap, self.floor, self.n_eff, f.n_coefs)
        f.sums = sums
        return f


def _periodic_in(fs: Sequence[Fitted]) -> list[Fitted]:
    return [f for f in fs if f.terms[0].kind == "force_periodic"]


def _alone(best: Fitted) -> list[dict]:
    return [_entry(best, best.terms[0], best.coefs[0], best.heldout_reduction)]


def _with_partner(
    runs: _Runs, singles: Sequence[Fitted], r0: np.ndarray, scored: _Scorer
) -> list[dict]:
    """The ranking: the best term, and its partner when the pair removes clearly more."""
    best = singles[0]
    two = _best_pair(runs, best, singles[1 : 1 + PAIR_POOL], r0, scored)
    if (
        two is not None
        and two.heldout_gap <= (1 - PAIR_GAIN) * best.heldout_gap
        and best.heldout_gap - two.heldout_gap >= PAIR_MATERIAL * scored.gap0
    ):
        return [
            _entry(best, two.terms[0], two.coefs[0], best.heldout_reduction),
            _entry(two, two.terms[1], two.coefs[1], two.heldout_reduction),
        ]
    return _alone(best)


def _best_pair(
    runs: _Runs, best: Fitted, others: Sequence[Fitted], r0: np.ndarray, scored: _Scorer
) -> Fitted | None:
    """The best term with each runner-up: the runner-up's coefficients refitted (one
    Gauss-Newton step) with the best term in place; the pair with the best criterion."""
    out = []
    for other in others:
        if other.terms[0] == best.terms[0]:
            continue
        fixed, fac = _pairs(best), best.factors
        t = other.terms[0]
        if isinstance(t, SensorTerm):
            pred = runs.pred(fixed, fac)
            found = [s for s in fit_sensor_terms(runs.prep, runs.segments, pred) if s.key == t.key]
            if not found:
                continue
            f = Fitted((*best.terms, found[0]), (*best.coefs, np.zeros(0)), 0.0, fac)
        else:  # (the plant runs first and a sensor term reads them, whatever the order)
            r = runs.residual([*fixed, *_pairs(other)], fac)
            c, _ = _gn_step(runs, fixed, t, other.coefs[0], r, fac)
            f = Fitted((*best.terms, t), (*best.coefs, c), 0.0, fac)
        f.fit_cost = float(np.mean(runs.residual(_pairs(f), fac) ** 2))
        out.append(scored(f))
    return min(out, key=lambda f: f.criterion) if out else None


def _entry(f: Fitted, term: PlantTerm | SensorTerm, c: np.ndarray, reduction: float) -> dict:
    """The contract's object: term, signal, description, coefficient (with ``unit``) and
    the held-out reduction (of this term together with the ones ranked above it)."""
    if isinstance(term, SensorTerm):
        coef, text, unit, shape = term.coefficient, term.description(), term.unit, term.kind
        extra: dict = {}
    else:
        coef, text = describe(term, c)
        unit, shape = term.unit, term.shape
        extra = {}
        if term.frequency_hz is not None:
            extra = {
                "frequency_hz": round(term.frequency_hz, 5),
                "phase_deg": round(math.degrees(math.atan2(-c[1], c[0])), 1),
            }
    return {
        "term": term.kind,
        "signal": term.signal,
        "shape": shape,
        "description": text,
        "coefficient": round(float(coef), 6),
        "unit": unit,
        **extra,
        "heldout_reduction": round(float(reduction), 4),
        **(
            {"tolerances_refitted_pct": {k: round(100 * (v - 1), 2) for k, v in f.factors.items()}}
            if f.factors is not None
            else {}
        ),
    }
