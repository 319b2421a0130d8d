"""Effects fitted as families (issue 18): the member that fits is found and reported."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.gap.diagnose import diagnose
from monitor.gap.fit.calibrate import apply
from monitor.gap.fit.candidates import Candidate, n_params
from monitor.gap.fit.families import MEMBERS, fit_family
from monitor.gap.report.document import member_names
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


def _hose_residual(cylinder_cm3_bar: float, line_cm3_bar: float):
    """Capacitance errors (cm^3/bar x 100) on a cylinder line and the pump line.  A series
    wall modulus E adds 0.3 L / E = 0.03 / E_GPa cm^3/bar to a cylinder line and
    0.5 L / E = 0.05 / E_GPa to the pump line (the nominal volumes)."""

    def residual(factors, effects):
        e = effects[0]
        if e.labels["law"] == "added_capacitance":
            cyl, line = (
                e.params["cylinder_capacitance_cm3_per_bar"],
                e.params["line_capacitance_cm3_per_bar"],
            )
        else:
            cyl, line = 0.03 / e.params["wall_modulus_gpa"], 0.05 / e.params["wall_modulus_gpa"]
        return 100.0 * np.array([cyl - cylinder_cm3_bar, line - line_cm3_bar])

    return residual


def test_cylinder_hoses_are_kept_only_above_their_floor():
    c = fit_family("hose_compliance", _hose_residual(0.03, 0.0), {})
    assert member_names(c) == {"hose_compliance": "cylinder_hoses"}
    assert c.effects[0].params["cylinder_capacitance_cm3_per_bar"] == pytest.approx(0.03, 1e-3)
    # Less than the least hose (0.01 cm^3/bar): that member fits better (0.006 off against
    # the series' 0.010 and 0.017 at 3 GPa) but ends on its floor, so the series stands.
    c = fit_family("hose_compliance", _hose_residual(0.004, 0.0), {})
    assert member_names(c) == {"hose_compliance": "series_modulus"}
    assert c.effects[0].params["wall_modulus_gpa"] == pytest.approx(3.0, rel=1e-3)


def test_every_member_knob_is_a_catalogue_parameter_within_its_range():
    from monitor.sim.effects import CATALOGUE

    for name, members in MEMBERS.items():
        for m in members:
            for k in m.knobs:
                if k.name == "static_excess_n":
                    continue
                spec = CATALOGUE[name].param(k.name)
                assert spec.low <= k.low < k.high <= spec.high, (name, m.name, k.name)
            for point in m.starts:
                for k, v in zip(m.knobs, point, strict=True):
                    assert k.low <= v <= k.high, (name, m.name, k.name, v)


def _diagnosed(changes: dict[str, float], fx: Effect, seed: int, effects: tuple[str, ...]):
    """A diagnosis, among ``effects``, of 120 s of boom cycles from the reference machine
    with the tolerance ``changes`` and effect ``fx``."""
    M = load_machine()
    rec = simulate(make_cycle("boom", 120.0, seed), apply(M, changes), effects=[fx], seed=seed)
    return diagnose(rec, M, effects=effects)


def test_oil_leaking_across_the_valve_clearances_is_named_with_that_member():
    # Thin oil leaking across the spool's clearances (no pump leakage): the pump-leak
    # formulation alone cannot make the held pressure's drift; the family's can.
    fx = Effect.make(
        "oil_viscosity",
        pump_leak_lpm_per_100bar=0.0,
        friction_share=0.0,
        valve_leak_lpm_per_100bar=0.3,
    )
    d = _diagnosed(
        {"mass": 1.03, "viscous_friction": 0.96, "valve_gain": 1.02},
        fx,
        4,
        ("oil_viscosity", "spool_dynamics", "load_variation"),
    )
    # A warm machine cannot tell thin oil from worn clearances: the leak's cause is
    # undecided, so the verdict names the mechanism (``unexplained``, the leak first).
    assert d.finding.verdict == "unexplained"
    assert d.finding.cause_check["mechanism"] == "leakage across the valve clearances"
    assert d.finding.cause_check["cause"] is None
    best = d.ranking.singles[0]
    assert member_names(best)["oil_viscosity"] in ("seal_and_valve", "all_paths")
    assert best.effects[0].params["valve_leak_lpm_per_100bar"] == pytest.approx(0.3, rel=0.3)


def test_entrained_air_on_a_machine_with_larger_volumes_is_found_with_one_local_fit():
    # Air softens the oil as larger volumes do: the volumes are fitted with it, and since
    # only friction keeps a second local fit (``TWO_LOCAL_FITS``), one local fit from the
    # best start must still find the air that was put in.
    fx = Effect.make("entrained_air", air_fraction=0.02)
    d = _diagnosed(
        {"volumes": 1.05, "mass": 0.97},
        fx,
        6,
        ("entrained_air", "hose_compliance", "load_variation"),
    )
    assert d.finding.verdict == "entrained_air"
    assert d.ranking.singles[0].effects[0].params["air_fraction"] == pytest.approx(0.02, rel=0.3)


def test_hoses_on_the_cylinder_lines_are_named_with_the_cylinder_hoses_member():
    # Hoses that add a capacitance of their own to the cylinder lines and none to the pump
    # line: the series modulus softens every volume in proportion to it, the pump line's
    # most, and cannot draw that; the family's second member can.
    fx = Effect.make(
        "hose_compliance",
        law="added_capacitance",
        line_capacitance_cm3_per_bar=0.0,
        cylinder_capacitance_cm3_per_bar=0.03,
    )
    d = _diagnosed(
        {"mass": 0.97, "valve_gain": 1.02},
        fx,
        8,
        ("entrained_air", "hose_compliance", "load_variation"),
    )
    assert d.finding.verdict == "hose_compliance"
    best = d.ranking.singles[0]
    assert member_names(best)["hose_compliance"] == "cylinder_hoses"
    p = best.effects[0].params
    assert p["cylinder_capacitance_cm3_per_bar"] == pytest.approx(0.03, rel=0.3)
    assert p["line_capacitance_cm3_per_bar"] == 0.0


def test_a_ringing_pump_is_named_with_the_second_order_member_and_its_frequency():
    # A swashplate that rings at 7 Hz after every command step (zeta 0.4): a first-order lag
    # cannot swing back, and a spool's ringing moves the cylinder's flow, not the pump's.
    fx = Effect.make(
        "pump_control_dynamics", law="second_order", natural_freq_hz=7.0, damping_ratio=0.4
    )
    d = _diagnosed(
        {"mass": 1.02, "valve_gain": 0.98},
        fx,
        9,
        ("pump_control_dynamics", "spool_dynamics", "sensor_lag"),
    )
    assert d.finding.verdict == "pump_control_dynamics"
    best = d.ranking.singles[0]
    assert member_names(best)["pump_control_dynamics"] == "second_order"
    assert best.effects[0].params["natural_freq_hz"] == pytest.approx(7.0, rel=0.15)
    assert best.effects[0].params["damping_ratio"] == pytest.approx(0.4, rel=0.3)
