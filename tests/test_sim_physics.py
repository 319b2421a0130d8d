"""The nominal boom loop against values worked out by hand from the reference machine.

Its nominal values are in docs/reference/contracts.md.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from sim_support import at, commands

from monitor.sim.machine import load_machine
from monitor.sim.simulate import run_plant, simulate

M = load_machine()
A_A = math.pi / 4 * 0.063**2  # cap side, m^2
A_B = math.pi / 4 * (0.063**2 - 0.036**2)  # rod side, m^2
PUMP_FULL_M3_S = 11e-6 * 2200 / 60  # 11 cm^3/rev at 2200 rpm = 24.2 L/min
KV = (20 / 60000) / math.sqrt(10e5)  # 20 L/min at 10 bar per edge


def test_full_spool_raise_speed_is_pump_flow_over_cap_area():
    # A closed-centre valve wide open passes all 24.2 L/min: v = Q / A_A = 0.1294 m/s.
    rec = simulate(commands([(0.5, 3.0, 100.0)], 3.0), M, seed=None)
    assert at(rec, "RodVel", 2.0) / 1e3 == pytest.approx(PUMP_FULL_M3_S / A_A, rel=1e-3)
    assert at(rec, "QP", 2.0) == pytest.approx(PUMP_FULL_M3_S * 60000, abs=0.01)


@pytest.mark.parametrize("spool_pct", [15.0, 20.0])
def test_metered_raise_speed_is_orifice_flow_over_area(spool_pct):
    # Below ~35 % the P->A edge meters: A_A v = Kv o sqrt(PP - PA), A_B v = Kv o sqrt(PB).
    rec = simulate(commands([(0.5, 3.0, spool_pct)], 3.0), M, seed=None)
    v = at(rec, "RodVel", 2.0) / 1e3
    o = spool_pct / 100
    dp_pa = (at(rec, "PP", 2.0) - at(rec, "PA", 2.0)) * 1e5
    assert v == pytest.approx(KV * o * math.sqrt(dp_pa) / A_A, rel=0.01)
    assert v == pytest.approx(KV * o * math.sqrt(at(rec, "PB", 2.0) * 1e5) / A_B, rel=0.01)
    # Force balance on the rod at constant speed: PA A_A - PB A_B = 6 kN + 2000 N s/m * v.
    force = at(rec, "PA", 2.0) * 1e5 * A_A - at(rec, "PB", 2.0) * 1e5 * A_B
    assert force == pytest.approx(6000 + 2000 * v, rel=0.01)


def test_relief_caps_pump_pressure_without_compensator():
    # Pump held at full displacement, spool closed: every drop goes over the relief, which
    # passes full flow at 220 bar (cracks at 210).
    machine = M.with_changes(compensator_enabled=False)
    rec = simulate(commands([], 2.0), machine, seed=None)
    pp = rec["PP"][100:]
    assert np.all((pp >= 210.0) & (pp <= 220.05))
    assert pp[-1] == pytest.approx(220.0, abs=0.05)


def test_compensator_holds_pump_pressure_in_its_band():
    # Dead-headed from the relief setting down: the compensator destrokes between 190 and
    # 200 bar, and with no leakage it settles at 200 bar, zero flow.
    machine = M.with_changes(compensator_enabled=True)
    rec = simulate(commands([(0.5, 1.5, 60.0)], 4.0), machine, seed=None)
    pp = rec["PP"][300:]
    assert np.all((pp >= 190.0) & (pp <= 200.05))
    assert at(rec, "QP", 4.0) == pytest.approx(0.0, abs=0.01)


def test_closed_spool_holds_pressures_and_rod():
    rec = simulate(commands([(0.5, 2.0, 70.0), (3.0, 4.0, -50.0)], 12.0), M, seed=None)
    hold = slice(800, None)  # from 8 s: spool centred since 4 s, the ringing has died out
    assert np.ptp(rec["RodPosTrue"][hold]) < 0.01  # mm
    assert np.ptp(rec["PA"][hold]) <= 0.02 and np.ptp(rec["PB"][hold]) <= 0.02
    # The trapped cap side carries the load: PA A_A - PB A_B = 6 kN.
    force = at(rec, "PA", 10.0) * 1e5 * A_A - at(rec, "PB", 10.0) * 1e5 * A_B
    assert force == pytest.approx(6000, rel=0.005)


@pytest.mark.parametrize("rod_pos_m", [0.05, 0.25, 0.45])
def test_hydraulic_natural_frequency(rod_pos_m):
    # A 30 ms spool pulse, then the closed spool traps both chambers: the load rings at
    # sqrt(beta/m (A_A^2/V_A + A_B^2/V_B)), 37-58 Hz here, above the 50 Hz Nyquist limit of
    # the 100 Hz samples, so look at the integrator's own states.
    trace = run_plant(
        commands([(0.1, 0.13, 10.0)], 2.0), M, rod_pos0_m=rod_pos_m, record_period_s=None
    )
    keep = trace.t_s > 0.3
    v = trace.rod_vel_m_s[keep] - trace.rod_vel_m_s[keep].mean()
    x = trace.rod_pos_m[keep].mean()
    dt = trace.t_s[1] - trace.t_s[0]
    n = 16 * len(v)
    spectrum = np.abs(np.fft.rfft(v * np.hanning(len(v)), n))
    f_peak = np.fft.rfftfreq(n, dt)[spectrum.argmax()]
    v_a = 0.3e-3 + A_A * x
    v_b = 0.3e-3 + A_B * (0.5 - x)
    f_theory = math.sqrt(1.5e9 / 400 * (A_A**2 / v_a + A_B**2 / v_b)) / (2 * math.pi)
    assert f_peak == pytest.approx(f_theory, rel=0.10)


def test_end_stops_hold_the_rod_inside_the_stroke():
    rec = simulate(commands([(0.2, 6.0, 100.0), (7.0, 12.0, -100.0)], 13.0), M, seed=None)
    assert rec["RodPosTrue"].max() == pytest.approx(500.0, abs=0.01)
    assert rec["RodPosTrue"].min() == pytest.approx(0.0, abs=0.01)
    assert at(rec, "RodPosTrue", 5.5) == pytest.approx(500.0, abs=0.01)
    # Stalled against the top stop the pump dead-heads: PP in the compensator band.
    assert 190.0 <= at(rec, "PP", 5.5) <= 200.05


def test_step_halving_changes_nothing_beyond_sensor_noise():
    # The accuracy check behind the default 200 us RK4 step (README, performance section).
    from monitor.sim.cycles import make_cycle

    cmds = make_cycle("step", 40.0, seed=4)
    coarse = simulate(cmds, M, seed=None)
    fine = simulate(cmds, M.with_changes(step_s=M.solver.step_s / 2), seed=None)
    for name in ("PP", "PA", "PB"):
        diff = coarse[name] - fine[name]
        assert np.sqrt(np.mean(diff**2)) < 0.05  # bar rms, vs 0.3 bar sensor noise
    assert np.abs(coarse["RodPosTrue"] - fine["RodPosTrue"]).max() < 0.05  # mm


def test_sensor_noise_matches_the_reference_sensors():
    rec = simulate(commands([], 20.0), M, seed=7)
    clean = simulate(commands([], 20.0), M, seed=None)
    assert np.std(rec["PA"] - clean["PA"]) == pytest.approx(0.3, rel=0.1)
    assert np.std(rec["RodPos"] - clean["RodPos"]) == pytest.approx(0.5, rel=0.1)
    # Quantised to the DBC's 0.01 bar.
    assert np.allclose(np.round(rec["PA"] * 100), rec["PA"] * 100, atol=1e-6)
    # Same seed, same trace.
    again = simulate(commands([], 20.0), M, seed=7)
    assert np.array_equal(again["PA"], rec["PA"])
