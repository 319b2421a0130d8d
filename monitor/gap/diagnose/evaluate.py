"""Simulations of segments for (tolerance factors, effects) hypotheses, and their held-out
scores: what every stage of the diagnosis asks of the simulator."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from monitor.gap.data.prepare import Prepared
from monitor.gap.data.reread import reread
from monitor.gap.data.segments import Segment
from monitor.gap.fit import calibrate as cal_mod
from monitor.gap.fit import score as S
from monitor.gap.fit import sensorcal
from monitor.gap.fit.candidates import Candidate, criterion, n_params
from monitor.gap.fit.predict import SENSOR_EFFECTS, SegmentPlant, moves_starts, sense
from monitor.gap.judge import basemis
from monitor.sim.effects import Effect
from monitor.sim.machine import MachineParams

Sums = tuple[S.SegmentSums, S.SegmentSums]


class Evaluator:
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

    def both_sums(self, factors: dict[str, float], effects: Sequence[Effect]) -> Sums:
        """Sums of the residual and of its smoothed (structured) part, one simulation."""
        pred = self.predict(factors, effects)
        return (
            S.segment_sums(self.prep, self.segments, pred),
            basemis.smoothed_sums(self.prep, self.segments, pred),
        )


class Readings:
    """Evaluators of the fit and held-out segments, per reading of the recording: as
    prepared (None) and as hypotheses reread it (``reread.py``), built when first asked."""

    def __init__(self, prep: Prepared, fit: tuple, held: tuple, machine: MachineParams):
        self.prep, self._parts, self.machine = prep, {"fit": fit, "held": held}, machine
        self._made: dict[tuple[str, int], Evaluator] = {}

    def _get(self, part: str, prep: Prepared | None) -> Evaluator:
        p = self.prep if prep is None else prep
        key = (part, id(p))  # the evaluator keeps ``p`` alive: its id stays its own
        if key not in self._made:
            self._made[key] = Evaluator(p, *self._parts[part])
        return self._made[key]

    def fit(self, prep: Prepared | None) -> Evaluator:
        return self._get("fit", prep)

    def held(self, prep: Prepared | None) -> Evaluator:
        return self._get("held", prep)

    def reread_for(self, effect: Effect) -> tuple[Prepared, sensorcal.Predict] | None:
        """The recording as a sensor calibration ``effect`` reads it, with its fit part's
        predictions (None: it reads the recording as prepared)."""
        other = reread(self.prep, effect, self.machine)
        return None if other is None else (other, self.fit(other).predict)


def score(c: Candidate, sums: S.SegmentSums, floor: np.ndarray, gap0: float, n_eff: float):
    """Set ``c``'s held-out scores from its held-out ``sums`` against the baseline's gap."""
    c.heldout_mse = sums.mse()
    c.heldout_gap = S.gap(c.heldout_mse, floor)
    c.heldout_reduction = S.reduction(gap0, c.heldout_gap)
    c.criterion = criterion(c.heldout_gap, floor, n_eff, n_params(c.effects, c.members))


class MemberJudge:
    """A family's members judged on the held-out part (``fit_family``'s ``judge``); the sums
    of each kept, so that scoring the member the family picks simulates nothing again."""

    def __init__(self, held_ev: Evaluator, floor: np.ndarray, gap0: float, n_eff: float):
        self.held_ev, self.floor, self.gap0, self.n_eff = held_ev, floor, gap0, n_eff
        self.kept: dict[int, Sums] = {}

    def __call__(self, c: Candidate) -> float:
        """A family member's held-out criterion."""
        self.kept[id(c)] = self.held_ev.both_sums(c.factors, c.effects)
        score(c, self.kept[id(c)][0], self.floor, self.gap0, self.n_eff)
        return c.criterion
