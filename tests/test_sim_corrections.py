"""The simulator's data-driven correction terms (``monitor.sim.corrections``) against values
worked out by hand from the reference machine (docs/reference/contracts.md)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from sim_support import at, commands

from monitor.sim.corrections import CORRECTIONS
from monitor.sim.faults import Fault
from monitor.sim.machine import BAR, LPM, load_machine
from monitor.sim.simulate import run_plant, simulate

M = load_machine()
A_A = math.pi / 4 * 0.063**2  # cap side, m^2
A_B = math.pi / 4 * (0.063**2 - 0.036**2)  # rod side, m^2
#: Raise, hold, lower, hold: every branch of the kernel runs.
PROFILE = [(0.5, 2.0, 60.0), (3.0, 4.0, -50.0), (4.5, 5.0, 15.0)]


def _arrays(trace) -> np.ndarray:
    return np.column_stack(
        [trace.pp_pa, trace.pa_pa, trace.pb_pa, trace.qp_m3_s, trace.rod_pos_m, trace.rod_vel_m_s]
    )


def test_zero_corrections_leave_the_simulation_bit_identical():
    cmds = commands(PROFILE, 6.0)
    plain = _arrays(run_plant(cmds, M))
    zeros = {name: 0.0 for name in CORRECTIONS}
    zeros["force_omega"] = 2 * math.pi  # a frequency without amplitude changes nothing
    assert np.array_equal(_arrays(run_plant(cmds, M, corrections=zeros)), plain)


def test_cross_port_leak_term_is_the_piston_wear_law():
    # Both are C (PA - PB): a fault of severity 1 has C = 5e-12 m^3/(s Pa) from t = 0.
    cmds = commands(PROFILE, 6.0)
    fault = run_plant(cmds, M, faults=[Fault("piston_wear", 1.0, 0.0, 0.0)])
    term = run_plant(cmds, M, corrections={"leak_ab_lin": 5e-12})
    np.testing.assert_allclose(_arrays(term), _arrays(fault), rtol=1e-9, atol=1e-9)
    assert not np.allclose(_arrays(term), _arrays(run_plant(cmds, M)))


@pytest.mark.parametrize("shape", ["lin", "sqrt"])
def test_pump_to_tank_leak_is_what_the_pump_delivers_at_dead_head(shape):
    # Spool closed: the pump holds PP near the compensator (190-200 bar) and delivers only
    # the leak, 2 L/min per 100 bar (laminar) or 2 L/min at 100 bar (orifice law).
    k = {"lin": 2 * LPM / (100 * BAR), "sqrt": 2 * LPM / math.sqrt(100 * BAR)}[shape]
    rec = simulate(commands([], 3.0), M, seed=None, corrections={f"leak_pt_{shape}": k})
    pp_bar = at(rec, "PP", 2.5)
    assert 190.0 < pp_bar < 200.0
    expected = 2.0 * (pp_bar / 100 if shape == "lin" else math.sqrt(pp_bar / 100))
    assert at(rec, "QP", 2.5) == pytest.approx(expected, rel=0.01)


def test_coulomb_term_adds_to_the_force_balance_at_constant_speed():
    # Metered raise at 20 % spool: PA A_A - PB A_B = 6 kN + 2000 N s/m v + 500 N.
    rec = simulate(
        commands([(0.5, 3.0, 20.0)], 3.0), M, seed=None, corrections={"force_sign": 500.0}
    )
    v = at(rec, "RodVel", 2.0) / 1e3
    assert v > 0.01
    force = (at(rec, "PA", 2.0) * A_A - at(rec, "PB", 2.0) * A_B) * BAR
    assert force == pytest.approx(6000 + 2000 * v + 500, rel=0.01)


def test_periodic_load_is_carried_by_the_held_rod():
    # Spool closed after a raise: the trapped oil holds the rod, so (quasi-statically: the
    # boom on its oil spring rings at ~40 Hz, damped within ~0.4 s by the viscous friction,
    # and a 0.5 Hz load moves it by ~0.04 mm) PA A_A - PB A_B = 6 kN + a cos(wt) + b sin(wt).
    a, b, w = 800.0, -600.0, 2 * math.pi * 0.5
    corr = {"force_cos": a, "force_sin": b, "force_omega": w}
    rec = simulate(commands([(0.5, 1.5, 50.0)], 7.0), M, seed=None, corrections=corr)
    for t in (4.2, 5.0, 5.9, 6.6):
        force = (at(rec, "PA", t) * A_A - at(rec, "PB", t) * A_B) * BAR
        expected = 6000 + a * math.cos(w * t) + b * math.sin(w * t)
        assert force == pytest.approx(expected, abs=30)  # readings in 0.01 bar steps
