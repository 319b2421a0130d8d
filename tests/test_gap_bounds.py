"""A tolerance at its bound is evidence, not a result (``report/bounds.py``): which
tolerance, at which bound, and which candidates it could be hiding, with what each one's
joint fit made of it."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from monitor.gap.diagnose import identify
from monitor.gap.diagnose.records import Absorbed
from monitor.gap.fit.candidates import Candidate, make_effect
from monitor.gap.report.bounds import HIDES, bound_lines, calibration_bounds


def _cand(effect: str, params: dict, factors: dict, reduction: float, gap: float) -> Candidate:
    c = Candidate((make_effect(effect, params),), factors, 1.0)
    c.heldout_reduction, c.heldout_gap = reduction, gap
    return c


class _Sums:
    def __init__(self, mse: np.ndarray):
        self._mse = mse

    def mse(self) -> np.ndarray:
        return self._mse


def _diag() -> SimpleNamespace:
    # The calibration took viscous friction to +30 % of its +-30 % band and the volumes to
    # -14.8 % of +-15 % (98.7 % of the band: at its bound); the mass stayed inside (+5 %).
    factors = {"viscous_friction": 1.30, "volumes": 0.852, "mass": 1.05}
    fric = _cand(
        "cylinder_friction",
        {"coulomb_n": 500.0, "static_excess_n": 300.0, "stribeck_velocity_mm_s": 10.0},
        {**factors, "viscous_friction": 1.06},
        0.20,
        3.0,
    )
    oil = _cand("oil_viscosity", {"pump_leak_lpm_per_100bar": 1.0}, factors, 0.05, 3.8)
    # Friction's own tolerances without it leave a held-out gap of 6 (floor 0): the friction
    # (gap 3) removes half of it, where against the calibrated machine it removed a fifth.
    absorbed = {
        fric.name: Absorbed({"viscous_friction": (1.30, 1.06)}, (_Sums(np.array([4.0, 2.0])), None))
    }
    return SimpleNamespace(
        tolerances=SimpleNamespace(factors=factors, floor=np.zeros(2)),
        ranking=SimpleNamespace(singles=[fric, oil], absorbed=absorbed),
        identifiability=[{"pair": ["cylinder_friction", "viscous_friction"], "cosine": 0.94}],
    )


def test_each_bound_names_its_side_and_the_effects_it_could_be_hiding():
    assert set(HIDES["viscous_friction"]) == {"cylinder_friction", "oil_viscosity"}
    assert set(HIDES["volumes"]) == {"entrained_air", "hose_compliance"}
    bounds = calibration_bounds(_diag())
    assert [(b["tolerance"], b["bound"]) for b in bounds] == [
        ("viscous_friction", "upper"),
        ("volumes", "lower"),
    ]
    visc = bounds[0]
    assert (visc["change_pct"], visc["band_pct"]) == (30.0, 30.0)
    assert visc["could_hide"] == ["cylinder_friction", "oil_viscosity"]
    fric, oil = visc["fits"]
    # Friction's fit took viscous friction off its bound (+6 %) and removes 50 % of what its
    # own tolerances leave; the identifiability of the pair is quoted.
    assert fric == {
        "effect": "cylinder_friction",
        "with_effect_pct": 6.0,
        "bound_with_effect": None,
        "heldout_reduction": 0.2,
        "beyond_own_tolerances": 0.5,
        "cosine": 0.94,
    }
    assert (oil["effect"], oil["bound_with_effect"]) == ("oil_viscosity", "upper")
    assert oil["with_effect_pct"] == 30.0
    assert "beyond_own_tolerances" not in oil
    # The volumes could hide air or a hose, neither of which was fitted here.
    assert bounds[1]["could_hide"] == ["entrained_air", "hose_compliance"]
    assert bounds[1]["fits"] == []


def test_the_summary_says_the_bound_and_what_each_hidden_candidate_made_of_it():
    lines = bound_lines(calibration_bounds(_diag()))
    assert lines[0].startswith("The calibration, before any candidate, left at a bound")
    assert lines[1] == (
        "  viscous_friction at its upper bound (+30.0 % of +-30 %): it could be hiding "
        "cylinder_friction, oil_viscosity"
    )
    assert lines[2] == (
        "    cylinder_friction: fitted with it, viscous_friction +6.0 % (inside its band); "
        "removes 50 % of the held-out gap the tolerances leave; signatures' cosine +0.94"
    )
    still = "oil_viscosity: fitted with it, viscous_friction +30.0 % (at its upper bound)"
    assert still in lines[3]
    assert lines[4] == (
        "  volumes at its lower bound (-14.8 % of +-15 %): it could be hiding "
        "entrained_air, hose_compliance"
    )
    assert bound_lines([]) == []


class _MassFitEv:
    """A residual linear in the mass factor and in a friction's Coulomb force, the two
    directions at a cosine of 0.8."""

    def __init__(self, u: np.ndarray, v: np.ndarray):
        self.u, self.v = u, v

    def residual(self, factors, effects):
        r = 1.0 + (factors.get("mass", 1.0) - 1.0) * self.u
        for e in effects:
            r = r + e.params["coulomb_n"] / 100.0 * self.v
        return r


def test_a_tolerance_at_its_bound_has_its_identifiability_measured_with_what_it_can_hide():
    rng = np.random.default_rng(5)
    u, w = rng.standard_normal(400), rng.standard_normal(400)
    w -= (w @ u) / (u @ u) * u
    v = 0.8 * u / np.linalg.norm(u) + 0.6 * w / np.linalg.norm(w)
    fit_ev = _MassFitEv(u, v)
    cal = SimpleNamespace(readings=SimpleNamespace(fit=lambda prep: fit_ev))
    fric = _cand(
        "cylinder_friction",
        {"coulomb_n": 500.0, "static_excess_n": 0.0, "stribeck_velocity_mm_s": 10.0},
        {},
        0.2,
        1.0,
    )
    inside = SimpleNamespace(baseline=SimpleNamespace(factors={"mass": 0.95}), singles=[fric])
    assert ["cylinder_friction", "mass"] not in [r["pair"] for r in identify.measure(cal, inside)]
    # The mass at its lower bound (-15 %): its signature is a step up (+u), cosine +0.8.
    at_bound = SimpleNamespace(baseline=SimpleNamespace(factors={"mass": 0.85}), singles=[fric])
    rows = {tuple(r["pair"]): r for r in identify.measure(cal, at_bound)}
    assert rows[("cylinder_friction", "mass")]["cosine"] == pytest.approx(0.8, abs=1e-3)
    # Pairs whose effect was not fitted (no single) are left out, not guessed.
    assert all("valve_deadband" not in p for p in rows)
