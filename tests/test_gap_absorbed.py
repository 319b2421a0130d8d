"""Which effects the calibration absorbed: a tolerance the effect trades off against
(``candidates.CONFOUNDED``) left at its bound by the calibration and moved off it by the
effect's own fit, by a quarter of the band or more.  Bands from ``calibrate.TOLERANCES``:
viscous friction +-30 %, volumes and mass +-15 %; a factor within 2 % of the band's edge
is at its bound."""

from __future__ import annotations

import numpy as np

from monitor.gap.diagnose.records import Absorbed
from monitor.gap.diagnose.verdict import calibration_absorbed
from monitor.gap.fit.candidates import Candidate
from monitor.gap.fit.score import SegmentSums
from monitor.gap.report.document import _absorbed
from monitor.gap.report.summary import _absorbed_line
from monitor.sim.effects import Effect


class _Held:
    """Stands in for the held-out evaluator: records which tolerances it simulated."""

    def __init__(self, calls: list):
        self.calls = calls

    def both_sums(self, factors, effects):
        self.calls.append((dict(factors), tuple(effects)))
        return ("whole", "smoothed")


class _Readings:
    def __init__(self):
        self.calls: list = []

    def held(self, prep):
        return _Held(self.calls)


def _c(name: str, **factors: float) -> Candidate:
    return Candidate((Effect.make(name),), factors, 0.0)


def test_a_bound_the_effect_fit_leaves_is_absorbed_and_simulated_without_the_effect():
    calibration = {"viscous_friction": 1.3, "mass": 0.85, "volumes": 0.85}
    friction = _c("cylinder_friction", viscous_friction=1.0, mass=0.85, volumes=0.85)
    readings = _Readings()
    out = calibration_absorbed([friction], calibration, readings)
    # Viscous friction left its +30 % bound; mass stayed at its -15 % bound (not moved).
    assert set(out) == {"cylinder_friction"}
    assert out["cylinder_friction"].tolerances == {"viscous_friction": (1.3, 1.0)}
    assert out["cylinder_friction"].sums == ("whole", "smoothed")
    # One held-out run: the effect's own tolerances, no effect.
    assert readings.calls == [(friction.factors, ())]


def test_the_opposite_bound_counts_as_moved_off():
    out = calibration_absorbed(
        [_c("cylinder_friction", viscous_friction=0.7)], {"viscous_friction": 1.3}, _Readings()
    )
    assert out["cylinder_friction"].tolerances == {"viscous_friction": (1.3, 0.7)}


def test_nothing_is_absorbed_inside_the_bands_or_where_the_effect_keeps_the_bound():
    readings = _Readings()
    cases = [
        # Inside the band (29 % of a 30 % band is 97 % of it: not at the bound).
        ([_c("cylinder_friction", viscous_friction=1.0)], {"viscous_friction": 1.29}),
        # The effect's fit keeps the bound, or moves less than a quarter of the band off it.
        ([_c("entrained_air", volumes=0.85)], {"volumes": 0.85}),
        ([_c("hose_compliance", volumes=1.146)], {"volumes": 1.15}),
        # At a bound the effect does not trade off against (air: volumes only).
        ([_c("entrained_air", viscous_friction=1.0)], {"viscous_friction": 1.3}),
        # A sensor effect trades off against no tolerance.
        ([_c("sensor_lag", mass=1.0)], {"mass": 0.85}),
    ]
    for singles, calibration in cases:
        assert calibration_absorbed(singles, calibration, readings) == {}
    assert readings.calls == []


def test_the_json_and_summary_say_which_bound_stood_in_and_what_the_effect_removed():
    floor = np.array([0.01, 0.01])
    # Its own tolerances without it: mean squared residual 0.21 per signal, a gap of 0.4;
    # the effect leaves 0.1: it removes 75 % of that gap.
    without = SegmentSums(np.full((1, 2), 21.0), np.full((1, 2), 100.0))
    friction = _c("cylinder_friction", viscous_friction=0.8)
    friction.heldout_gap = 0.1
    absorbed = {friction.name: Absorbed({"viscous_friction": (1.3, 0.8)}, (without, without))}
    block = _absorbed(friction, absorbed, floor)["absorbed"]
    assert block == {
        "effect": "cylinder_friction",
        "tolerances": {"viscous_friction": {"calibration_pct": 30.0, "with_effect_pct": -20.0}},
        "heldout_reduction": 0.75,
    }
    line = _absorbed_line(block)
    assert "viscous_friction +30 % (its bound), -20 % when fitted" in line and "75 %" in line
    # Nothing to say when the verdict is another effect, or nothing was absorbed.
    assert _absorbed(None, absorbed, floor) == {}
    assert _absorbed(friction, {}, floor) == {}
