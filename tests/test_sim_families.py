"""Effect families (issue 18): the new members' physics, and nothing else moved."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sim_support import at, commands

from monitor.sim import kernel as K
from monitor.sim.effects import Effect
from monitor.sim.faults import Fault
from monitor.sim.machine import load_machine
from monitor.sim.pack import pack_params
from monitor.sim.simulate import simulate

M = load_machine()
REF = Path(__file__).parent / "data" / "sim_before_families.npz"


def test_defaults_of_the_new_parameters_leave_every_trace_as_before():
    # Traces written by the simulator before the family parameters existed (same profile).
    ref = np.load(REF)
    cmds = commands(
        [(0.5, 2.0, 70.0), (2.0, 3.0, 0.0), (3.0, 4.5, -60.0), (5.0, 5.3, 30.0)],
        7.0,
        oil_temp_c=65.0,
    )
    for name in ("entrained_air", "oil_viscosity", "cylinder_friction", "load_variation"):
        rec = simulate(cmds, M, effects=[Effect.make(name)], seed=None)
        for sig in ("PP", "PA", "PB", "QP", "RodPosTrue"):
            # Equal to the last bits but for rounding: the compiled kernel may fuse a
            # multiply-add differently when code around it changes (2e-13 mm of RodPos
            # with the correction terms beside the load); any change of a formula moves
            # these traces by orders of magnitude more.
            np.testing.assert_allclose(
                np.asarray(rec[sig], dtype=np.float64),
                ref[f"{name}.{sig}"],
                rtol=1e-12,
                atol=1e-9,
                err_msg=f"{name} {sig}",
            )


def _hold(oil_temp_c: float) -> object:
    return commands([(0.5, 1.5, 60.0)], 8.0, oil_temp_c=oil_temp_c)


def test_piston_seal_leakage_at_40_degc_is_the_piston_wear_leak_of_the_same_coefficient():
    # 1.5 L/min at 100 bar = 1.5/60000 m^3/s / 1e7 Pa = 2.5e-12 m^3/(s Pa): piston_wear at
    # severity 0.5 (5e-12 at 1).  At 40 degC the viscosity ratio is 1.
    base = dict(pump_leak_lpm_per_100bar=0.0, friction_share=0.0)
    seal = Effect.make("oil_viscosity", piston_leak_lpm_per_100bar=1.5, **base)
    plain = Effect.make("oil_viscosity", **base)
    a = simulate(_hold(40.0), M, effects=[seal], seed=None)
    b = simulate(_hold(40.0), M, faults=[Fault("piston_wear", 0.5)], effects=[plain], seed=None)
    for sig in ("PA", "PB", "RodPosTrue"):
        assert np.allclose(a[sig], b[sig], rtol=1e-6, atol=1e-6), sig


@pytest.mark.parametrize(("temp_c", "nu_cst"), [(40.0, 46.0), (100.0, 6.8)])
def test_valve_clearance_leak_is_laminar_and_follows_viscosity(temp_c, nu_cst):
    # Centred spool, held: the pump feeds only the clearances P->A and P->B, each
    # k (pp - p) with k = 0.5 L/min per 100 bar at 46 cSt, times 46/nu (laminar).
    k = 0.5 / 60000 / 1e7 * 46.0 / nu_cst
    fx = Effect.make(
        "oil_viscosity",
        pump_leak_lpm_per_100bar=0.0,
        friction_share=0.0,
        valve_leak_lpm_per_100bar=0.5,
    )
    rec = simulate(_hold(temp_c), M, effects=[fx], seed=None)
    pp, pa, pb = (at(rec, s, 7.0) * 1e5 for s in ("PP", "PA", "PB"))
    expected_lpm = k * ((pp - pa) + (pp - pb)) * 60000
    assert expected_lpm > 0.05
    assert at(rec, "QP", 7.0) == pytest.approx(expected_lpm, rel=0.03)


def _friction_force(exponent: float, v_m_s: float) -> float:
    """Friction the kernel applies at rod speed v (from dv/dt with no pressure force)."""
    fx = Effect.make(
        "cylinder_friction",
        coulomb_n=500.0,
        static_n=800.0,
        stribeck_velocity_mm_s=10.0,
        stribeck_exponent=exponent,
    )
    prm = pack_params(M, [fx])
    y = np.zeros(K.N_STATES)
    y[K.S_X], y[K.S_V] = 0.25, v_m_s
    u = np.array([0.0, 1.0, 2200 / 60, 1.0, 0.0, 1.0, 0.0])
    dy = np.zeros(K.N_STATES)
    K.rhs(y, u, prm, dy)
    drive = -(M.load.gravity_load_n + prm[K.SLOPE] * (0.25 - M.load.reference_rod_pos_m))
    return drive - M.load.mass_kg * dy[K.S_V]


def test_stribeck_exponent_shapes_the_decay_from_static_to_coulomb():
    # At v = 2 vs = 20 mm/s: viscous 2000 N s/m x 0.02 = 40 N, plus 500 + 300 exp(-2^e)
    # (the sign's tanh(20/0.5) is 1): e = 2 gives 545.49 N, e = 1 gives 580.60 N.
    assert _friction_force(2.0, 0.02) == pytest.approx(40 + 500 + 300 * np.exp(-4.0), rel=1e-9)
    assert _friction_force(1.0, 0.02) == pytest.approx(40 + 500 + 300 * np.exp(-2.0), rel=1e-9)


def test_load_curvature_adds_its_quadratic_force_to_the_held_pressure():
    # 0.05 N/mm^2 at 200 mm past the 250 mm reference: 2000 N more on a 63 mm bore
    # (3.1173e-3 m^2): 6.416 bar more in A to hold the rod there.
    area = np.pi / 4 * 0.063**2
    held = {}
    for curv in (0.0, 0.05):
        fx = Effect.make("load_variation", slope_n_per_mm=0.0, curvature_n_per_mm2=curv)
        rec = simulate(commands([], 3.0), M, effects=[fx], seed=None, rod_pos0_m=0.45)
        held[curv] = at(rec, "PA", 2.5)
    assert held[0.05] - held[0.0] == pytest.approx(2000.0 / area / 1e5, rel=0.01)


def test_dissolving_air_is_stiff_above_its_pressure_and_softer_below():
    # Gas volume per liquid volume g(p) = a theta(p) (p0/p)^(1/n) with theta falling
    # linearly from 1 at atmosphere to 0 at the dissolving pressure; the node's compliance
    # per volume is (1/beta - g'(p)) / (1 + g(p)), g' by central differences here.
    a, n, p_diss_bar = 0.02, 1.4, 30.0
    fx = Effect.make(
        "entrained_air",
        air_fraction=a,
        polytropic_index=n,
        law="dissolving",
        dissolved_at_bar=p_diss_bar,
    )
    prm = pack_params(M, [fx])
    beta, p0, pc = M.oil.bulk_modulus_pa, 101325.0, p_diss_bar * 1e5 + 101325.0

    def g(p_gauge: float) -> float:
        pabs = p_gauge + p0
        theta = min(max((pc - pabs) / (pc - p0), 0.0), 1.0)
        return a * theta * (p0 / pabs) ** (1 / n)

    for p_bar in (2.0, 10.0, 25.0):
        p, h = p_bar * 1e5, 10.0
        dg = (g(p + h) - g(p - h)) / (2 * h)
        expected = (1 / beta - dg) / (1 + g(p))
        assert K._compliance(p, 1.0, 0.0, 0.0, prm) == pytest.approx(expected, rel=1e-5)
    assert K._compliance(40e5, 1.0, 0.0, 0.0, prm) == pytest.approx(1 / beta, rel=1e-12)
    free = pack_params(M, [Effect.make("entrained_air", air_fraction=a, polytropic_index=n)])
    assert K._compliance(10e5, 1.0, 0.0, 0.0, prm) > K._compliance(10e5, 1.0, 0.0, 0.0, free)


def test_second_order_pump_displacement_is_a_mass_spring_damper_on_its_target():
    # x'' = wn^2 (target - x) - 2 zeta wn x'; target = the displacement command (50 %)
    # while the line is below the compensator's start (20 bar here).  At x = 0.2, x' = 1.5/s,
    # 8 Hz and zeta 0.3: wn = 50.265 rad/s, x'' = 2526.6 x 0.3 - 30.159 x 1.5 = 712.74 /s^2.
    fx = Effect.make(
        "pump_control_dynamics", law="second_order", natural_freq_hz=8.0, damping_ratio=0.3
    )
    prm = pack_params(M, [fx])
    y = np.zeros(K.N_STATES)
    y[K.S_PP], y[K.S_X], y[K.S_DISP], y[K.S_DISP_RATE] = 20e5, 0.25, 0.2, 1.5
    u = np.array([0.0, 0.5, 2200 / 60, 1.0, 0.0, 1.0, 0.0, 0.0])
    dy = np.zeros(K.N_STATES)
    K.rhs(y, u, prm, dy)
    wn = 2 * np.pi * 8.0
    assert dy[K.S_DISP] == pytest.approx(1.5)
    assert dy[K.S_DISP_RATE] == pytest.approx(wn**2 * 0.3 - 2 * 0.3 * wn * 1.5, rel=1e-12)
    assert dy[K.S_DISP_RATE] == pytest.approx(712.74, rel=1e-4)


def test_a_ringing_pump_overshoots_where_a_lag_does_not():
    # A step of the displacement command from 30 % to 60 % against a low load: the pump
    # flow of an underdamped pump (zeta 0.2: 53 % overshoot of the step, exp(-pi zeta /
    # sqrt(1 - zeta^2))) passes its settled value; a first-order lag approaches it from below.
    cmds = commands([(0.5, 6.0, 100.0)], 6.0)
    cmds.columns["PumpDispCmd"] = np.where(cmds.t < 3.0, 30.0, 60.0)
    lag = Effect.make("pump_control_dynamics", time_constant_ms=60.0)
    ring = Effect.make(
        "pump_control_dynamics", law="second_order", natural_freq_hz=4.0, damping_ratio=0.2
    )
    after = (cmds.t > 3.0) & (cmds.t < 4.5)
    recs = {
        name: simulate(cmds, M, effects=[fx], seed=None)
        for name, fx in (("lag", lag), ("ring", ring))
    }
    settled = {name: at(rec, "QP", 5.8) for name, rec in recs.items()}
    peak = {name: float(np.max(rec["QP"][after])) for name, rec in recs.items()}
    assert settled["ring"] == pytest.approx(settled["lag"], rel=0.02)
    step = settled["lag"] - at(recs["lag"], "QP", 2.9)
    assert peak["lag"] <= settled["lag"] + 0.02 * step
    assert peak["ring"] > settled["ring"] + 0.3 * step
