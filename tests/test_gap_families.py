"""Effects fitted as families (issue 18): the member that fits is found and reported."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.gap.calibrate import apply
from monitor.gap.candidates import Candidate, n_params
from monitor.gap.diagnose import diagnose
from monitor.gap.families import MEMBERS, fit_family
from monitor.gap.report import member_names
from monitor.sim.cycles import make_cycle
from monitor.sim.effects import Effect
from monitor.sim.machine import load_machine
from monitor.sim.simulate import simulate

X_MM = np.linspace(-250.0, 250.0, 41)


def _load_residual(slope: float, curvature: float):
    """Force error (kN) along the stroke against a load of the given shape."""

    def residual(factors, effects):
        p = effects[0].params
        model = p["slope_n_per_mm"] * X_MM + p["curvature_n_per_mm2"] * X_MM**2
        return (model - (slope * X_MM + curvature * X_MM**2)) / 1e3

    return residual


def _by_cost_and_size(c: Candidate) -> float:
    # a stand-in for the held-out criterion: fit cost plus a price per fitted parameter
    return c.fit_cost + 1e-4 * n_params(c.effects, c.members)


def test_a_curved_load_is_fitted_by_the_curved_member_with_its_values():
    c = fit_family("load_variation", _load_residual(6.0, 0.03), {}, judge=_by_cost_and_size)
    assert c.members[0].name == "curved"
    p = c.effects[0].params
    assert p["slope_n_per_mm"] == pytest.approx(6.0, abs=0.05)
    assert p["curvature_n_per_mm2"] == pytest.approx(0.03, abs=5e-4)
    assert member_names(c) == {"load_variation": "curved"}


def test_a_straight_load_keeps_the_linear_member_when_size_has_a_price():
    c = fit_family("load_variation", _load_residual(-8.0, 0.0), {}, judge=_by_cost_and_size)
    assert c.members[0].name == "linear"
    assert c.effects[0].params["slope_n_per_mm"] == pytest.approx(-8.0, abs=0.05)
    assert n_params(c.effects, c.members) == 1


def test_every_member_knob_is_a_catalogue_parameter_within_its_range():
    from monitor.sim.effects import CATALOGUE

    for name, members in MEMBERS.items():
        for m in members:
            for k in m.knobs:
                if k.name == "static_excess_n":
                    continue
                spec = CATALOGUE[name].param(k.name)
                assert spec.low <= k.low < k.high <= spec.high, (name, m.name, k.name)


def test_oil_leaking_across_the_valve_clearances_is_named_with_that_member():
    # Thin oil leaking across the spool's clearances (no pump leakage): the pump-leak
    # formulation alone cannot make the held pressure's drift; the family's can.
    M = load_machine()
    machine = apply(M, {"mass": 1.03, "viscous_friction": 0.96, "valve_gain": 1.02})
    fx = Effect.make(
        "oil_viscosity", pump_leak_lpm_per_100bar=0.0, friction_share=0.0,
        valve_leak_lpm_per_100bar=0.3,
    )  # fmt: skip
    rec = simulate(make_cycle("boom", 120.0, 4), machine, effects=[fx], seed=4)
    d = diagnose(rec, M, effects=("oil_viscosity", "spool_dynamics", "load_variation"))
    assert d.verdict == "oil_viscosity"
    best = d.singles[0]
    assert member_names(best)["oil_viscosity"] in ("seal_and_valve", "all_paths")
    assert best.effects[0].params["valve_leak_lpm_per_100bar"] == pytest.approx(0.3, rel=0.3)


def test_entrained_air_on_a_machine_with_larger_volumes_is_found_with_one_local_fit():
    # Air softens the oil as larger volumes do: the volumes are fitted with it, and since
    # only friction keeps a second local fit (``TWO_LOCAL_FITS``), one local fit from the
    # best start must still find the air that was put in.
    M = load_machine()
    machine = apply(M, {"volumes": 1.05, "mass": 0.97})
    fx = Effect.make("entrained_air", air_fraction=0.02)
    rec = simulate(make_cycle("boom", 120.0, 6), machine, effects=[fx], seed=6)
    d = diagnose(rec, M, effects=("entrained_air", "hose_compliance", "load_variation"))
    assert d.verdict == "entrained_air"
    assert d.singles[0].effects[0].params["air_fraction"] == pytest.approx(0.02, rel=0.3)
