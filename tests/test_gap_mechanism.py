"""Mechanism first, cause second (``judge/mechanism.py``, ``diagnose/cause.py``): what the
JSON's ``mechanism`` says for each kind of verdict, and when a leak is put down to wear."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from monitor.gap.data.segments import Segment
from monitor.gap.diagnose import identify
from monitor.gap.diagnose.cause import FLAT_OIL, LeakCause, flat_member
from monitor.gap.fit.candidates import Candidate, default_member, make_effect
from monitor.gap.judge import mechanism
from monitor.gap.judge.delays import delays_ms, machine_late
from monitor.gap.report.summary import _mechanism_lines
from monitor.sim.pack import viscosity_cst


def _leak(pump: float = 3.0) -> Candidate:
    e = make_effect("oil_viscosity", {"pump_leak_lpm_per_100bar": pump, "friction_share": 0.2})
    c = Candidate((e,), {}, 1.0)
    c.heldout_reduction = 0.8
    return c


def _flat(reduction: float) -> Candidate:
    c = _leak(2.4)
    c.heldout_reduction = reduction
    return c


def test_the_flat_oil_does_not_follow_the_temperature_and_keeps_the_paths():
    nu40, nu100 = dict(FLAT_OIL)["nu40_cst"], dict(FLAT_OIL)["nu100_cst"]
    # Over a warm-up from 15 to 60 degC: the flat oil within 0.1 %, ISO VG 46 by 4x.
    t = np.array([15.0, 60.0])
    assert np.all(np.abs(viscosity_cst(t, nu40, nu100) / nu40 - 1) < 1e-3)
    ratio = viscosity_cst(t, 46.0, 6.8) / 46.0
    assert ratio[0] / ratio[1] > 4
    m = flat_member(default_member("oil_viscosity"))
    assert m.knobs == default_member("oil_viscosity").knobs
    e = make_effect("oil_viscosity", {"pump_leak_lpm_per_100bar": 2.0, "friction_share": 0}, m)
    assert (e.params["nu40_cst"], e.params["nu100_cst"]) == (nu40, nu100)


@pytest.mark.parametrize(("share", "cause"), [(0.99, "wear"), (0.01, "oil_viscosity"), (0.5, None)])
def test_the_cause_is_what_the_bootstrap_settles_and_undecided_otherwise(share, cause):
    chk = LeakCause("pump_leak_lpm_per_100bar", 32.0, _leak(), _flat(0.9), share)
    assert chk.cause == cause
    d = chk.as_dict()
    assert d["mechanism"] == "pump leakage" and d["signal"] == "P->tank"
    assert d["cause"] == cause and d["oil_temp_span_c"] == 32.0
    if cause is None:
        assert "longer warm-up" in d["evidence"]


def test_a_warm_machine_cannot_tell_viscosity_from_wear_and_says_which_run_would():
    chk = LeakCause("pump_leak_lpm_per_100bar", 3.0, _leak())
    assert chk.cause is None
    assert "warm-up run" in chk.as_dict()["evidence"]
    report = {
        "verdict": "oil_viscosity",
        "member": "pump_leak",
        "ranking": [],
        "calibrated": {},
        "cause_check": chk.as_dict(),
    }
    m = mechanism.describe(report)
    assert m["name"] == "pump leakage" and m["cause"] == "oil_viscosity"
    assert "warm-up" in m["separating_recording"]


def test_a_worn_leak_leads_with_the_mechanism_and_names_wear_as_its_cause():
    chk = LeakCause("pump_leak_lpm_per_100bar", 34.0, _leak(), _flat(0.85), 0.995)
    report = {
        "verdict": "unexplained",
        "suggestion": [
            {
                "term": "leakage",
                "signal": "P->tank",
                "description": "pump leakage that does not follow the oil temperature (wear)",
                "heldout_reduction": 0.85,
                "cause": "wear",
            }
        ],
        "cause_check": chk.as_dict(),
        "calibrated": {},
    }
    m = mechanism.describe(report)
    # Mechanism first (the pump's leak, as an oil_viscosity verdict names it), then the cause.
    assert (m["name"], m["signal"], m["cause"]) == ("pump leakage", "P->tank", "wear")
    assert "does not follow the viscosity" in m["decided_by"]
    assert [(c["cause"], c["status"]) for c in m["causes"]] == [
        ("oil_viscosity", "rejected"),
        ("wear", "kept"),
    ]
    assert m["cause_decided"] is True


def test_a_tolerance_at_its_bound_is_reported_as_evidence_for_the_effects_it_can_hide():
    report = {
        "verdict": "cylinder_friction",
        "ranking": [
            {"effect": "cylinder_friction", "heldout_reduction": 0.6, "criterion": -500.0},
            {"effect": "oil_viscosity", "heldout_reduction": 0.2, "criterion": -420.0},
        ],
        "calibrated": {
            "viscous_friction": {"change_pct": 30.0, "at_bound": True},
            "mass": {"change_pct": 2.0, "at_bound": False},
        },
    }
    m = mechanism.describe(report)
    assert m["name"] == "rod friction"
    assert [c["cause"] for c in m["causes"]] == ["cylinder_friction", "oil_viscosity"]
    (line,) = m["bounds"]
    assert line.startswith("viscous_friction at its +30 % bound")
    assert "cylinder_friction" in line and "oil_viscosity" in line
    # Decided on the criterion alone: the recording that would separate is named.
    assert "80.0 behind" in m["decided_by"] and "reversals" in m["separating_recording"]


def test_none_has_no_mechanism():
    assert mechanism.describe({"verdict": "none", "calibrated": {}}) is None


def _traces(delay_samples: dict[str, int], n: int = 3000):
    """A smooth random drive per signal (the 'simulator') and its reading delayed."""
    rng = np.random.default_rng(4)
    sim, meas = {}, {}
    for name, d in delay_samples.items():
        x = np.convolve(rng.standard_normal(n + 200), np.hanning(15), mode="same")[100:-100]
        sim[name] = x
        meas[name] = np.concatenate([np.full(d, x[0]), x[: n - d]])
    return SimpleNamespace(meas=meas), sim


@pytest.mark.parametrize(
    ("rod", "says"), [(0, "a lag of the readings (sensor)"), (3, "the machine itself is late")]
)
def test_a_lag_the_rod_does_not_share_is_the_sensors(rod, says):
    lag = {"PP": 3, "PA": 3, "PB": 3, "QP": 3, "RodVel": rod}
    prep, sim = _traces(lag)
    segs = [Segment(i, i + 500, True) for i in range(0, 2500, 500)]
    d = delays_ms(prep, segs, sim)
    # 3 samples of 10 ms; the parabola puts the peak within a millisecond of it.
    assert d == {k: pytest.approx(10.0 * v, abs=1.0) for k, v in lag.items()}
    assert says in mechanism.timing(d)
    assert machine_late(d) is (rod == 3)
    assert machine_late({k: v for k, v in d.items() if k != "RodVel"}) is None


def test_the_summary_says_the_mechanism_then_the_cause_and_the_recording_that_would_decide():
    m = {
        "name": "pump leakage",
        "cause": "oil_viscosity",
        "decided_by": "the oil temperature spans 3 degC",
        "separating_recording": "a warm-up run",
    }
    assert _mechanism_lines(m) == [
        "Mechanism: pump leakage; cause: oil_viscosity (the oil temperature spans 3 degC)",
        "To tell the causes apart, record: a warm-up run",
    ]
    assert _mechanism_lines(None) == []


class _FitEv:
    """A residual linear in viscous friction and in a friction's Coulomb force, with the
    two directions at a known angle (the look-alikes of ``identify.PAIRS``' first pair)."""

    def __init__(self, u: np.ndarray, v: np.ndarray):
        self.u, self.v = u, v

    def residual(self, factors, effects):
        r = 1.0 + 0 * self.u + (factors.get("viscous_friction", 1.0) - 1.0) * self.u
        for e in effects:
            r = r + e.params["coulomb_n"] / 100.0 * self.v
        return r


def test_identifiability_is_the_angle_between_what_each_look_alike_changes():
    rng = np.random.default_rng(2)
    u = rng.standard_normal(400)
    w = rng.standard_normal(400)
    w -= (w @ u) / (u @ u) * u
    v = 0.8 * u / np.linalg.norm(u) + 0.6 * w / np.linalg.norm(w)  # cosine 0.8 with u
    fit_ev = _FitEv(u, v)
    cal = SimpleNamespace(readings=SimpleNamespace(fit=lambda prep: fit_ev))
    friction = Candidate(
        (make_effect("cylinder_friction", {"coulomb_n": 500.0, "static_excess_n": 0.0}),), {}, 0.0
    )
    scores = SimpleNamespace(
        baseline=SimpleNamespace(factors={"viscous_friction": 1.3}), singles=[friction]
    )
    (row,) = identify.measure(cal, scores)
    assert row["pair"] == ["cylinder_friction", "viscous_friction"]
    # viscous friction at its upper bound: its signature is a step down (-u), so -0.8.
    assert row["cosine"] == pytest.approx(-0.8, abs=1e-3)
    assert row["unique_share"] == pytest.approx(0.36, abs=1e-3)


def test_an_unexplained_gap_led_by_a_sensor_term_names_the_sensor_and_signal():
    first = {
        "term": "sensor_delay",
        "signal": "QP",
        "description": "QP read 20 ms late",
        "heldout_reduction": 0.4,
    }
    m = mechanism.describe({"verdict": "unexplained", "suggestion": [first], "calibrated": {}})
    assert (m["name"], m["cause"]) == ("sensor delay on QP", "outside the catalogue")


def test_a_verdict_the_rods_timing_decided_says_so_and_asks_for_no_other_recording():
    lags = {"PP": 33.1, "PA": 49.4, "PB": 35.6, "QP": 37.4, "RodVel": 44.7}
    report = {
        "verdict": "spool_dynamics",
        "ranking": [],
        "calibrated": {},
        "delays_ms": lags,
        "timing_check": {"delays_ms": lags, "rod_shares_lag": True},
    }
    m = mechanism.describe(report)
    assert "the machine itself is late" in m["decided_by"]
    assert m["separating_recording"] is None and m["timing"] == m["decided_by"]


def _walther_cst(t_c: float, nu40: float, nu100: float) -> float:
    """ASTM D341 by hand: log10(log10(nu + 0.7)) is linear in log10 of the absolute
    temperature, through the oil's 40 and 100 degC viscosities."""
    x40, x100 = np.log10(313.15), np.log10(373.15)
    y40, y100 = (np.log10(np.log10(nu + 0.7)) for nu in (nu40, nu100))
    y = y40 + (y100 - y40) * (np.log10(t_c + 273.15) - x40) / (x100 - x40)
    return float(10 ** (10**y) - 0.7)


def test_a_warm_up_says_how_far_a_viscous_leak_would_swing_and_judges_both_causes():
    # A 3 L/min per 100 bar pump leak (at 40 degC, ISO VG 46) over a 30 -> 60 degC warm-up.
    chk = LeakCause("pump_leak_lpm_per_100bar", 30.0, _leak(3.0), _flat(0.85), 0.99, (30.0, 60.0))
    nu30, nu60 = _walther_cst(30.0, 46.0, 6.8), _walther_cst(60.0, 46.0, 6.8)
    # An ISO VG 46 oil: about 75 cSt at 30 degC, 21 at 60 (a 3.7-fold thinning).
    assert 3.0 < nu30 / nu60 < 4.5
    d = chk.as_dict()
    assert d["oil_temp_c"] == [30.0, 60.0]
    assert d["viscosity_ratio"] == pytest.approx(nu30 / nu60, rel=2e-3)
    cold, warm = d["viscous_leak_cold_warm_lpm_per_100bar"]
    assert cold == pytest.approx(3.0 * 46.0 / nu30, rel=2e-3)
    assert warm == pytest.approx(3.0 * 46.0 / nu60, rel=2e-3)
    assert f"thins {nu30 / nu60:.1f}-fold" in d["evidence"]
    assert [(c["cause"], c["status"]) for c in d["causes"]] == [
        ("oil_viscosity", "rejected"),
        ("wear", "kept"),
    ]
    # A leak the constant law cannot beat: viscosity kept, wear rejected.
    visc = LeakCause("pump_leak_lpm_per_100bar", 30.0, _leak(3.0), _flat(0.4), 0.01, (30.0, 60.0))
    assert [c["status"] for c in visc.as_dict()["causes"]] == ["kept", "rejected"]
    m = mechanism.describe(
        {"verdict": "oil_viscosity", "ranking": [], "calibrated": {}, "cause_check": visc.as_dict()}
    )
    assert (m["name"], m["cause"], m["cause_decided"]) == ("pump leakage", "oil_viscosity", True)
    assert m["separating_recording"] is None
    lines = _mechanism_lines(m)
    assert lines[1].startswith("Causes: oil_viscosity (leak ~ 1/viscosity (laminar)")
    assert lines[1].endswith(
        "wear (leak constant in oil temperature, removes 40 % of the held-out gap): rejected"
    )


def test_a_narrow_temperature_range_leaves_the_cause_undecided_and_asks_for_a_warm_up():
    chk = LeakCause("pump_leak_lpm_per_100bar", 2.0, _leak(3.0), temps_c=(45.0, 47.0))
    m = mechanism.describe(
        {"verdict": "oil_viscosity", "ranking": [], "calibrated": {}, "cause_check": chk.as_dict()}
    )
    assert m["cause_decided"] is False
    assert [c["status"] for c in m["causes"]] == ["undecided", "undecided"]
    assert "warm-up" in m["separating_recording"]
