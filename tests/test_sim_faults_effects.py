"""Each fault and effect moves the traces the way the physics says it should."""

from __future__ import annotations

import numpy as np
import pytest
from sim_support import at, commands

from monitor.errors import ConfigError
from monitor.sim.effects import CATALOGUE, Effect, parse_effect
from monitor.sim.faults import Fault, parse_fault
from monitor.sim.machine import load_machine
from monitor.sim.simulate import run_plant, simulate

M = load_machine()
RAISE_HOLD = commands([(0.5, 1.5, 60.0)], 8.0)


def test_piston_wear_slows_extension_pulls_ports_together_and_lets_load_creep():
    nominal = simulate(RAISE_HOLD, M, seed=None)
    worn = simulate(RAISE_HOLD, M, faults=[Fault("piston_wear", 1.0)], seed=None)
    # Under load, part of the pump flow leaks A->B instead of pushing the rod.
    assert at(worn, "RodVel", 1.2) < 0.99 * at(nominal, "RodVel", 1.2)
    # Held: the leak pulls PA and PB together ...
    gap_nominal = at(nominal, "PA", 7.0) - at(nominal, "PB", 7.0)
    gap_worn = at(worn, "PA", 7.0) - at(worn, "PB", 7.0)
    assert gap_nominal > 10.0 and abs(gap_worn) < 1.0
    # ... and the held load creeps down while the nominal rod stays.
    creep_worn = at(worn, "RodPosTrue", 7.5) - at(worn, "RodPosTrue", 3.0)
    creep_nominal = at(nominal, "RodPosTrue", 7.5) - at(nominal, "RodPosTrue", 3.0)
    assert creep_worn < -0.5 and abs(creep_nominal) < 0.01
    # QP stays near zero while it creeps: the leak is internal to the cylinder.
    assert at(worn, "QP", 7.0) == pytest.approx(0.0, abs=0.05)


def test_spool_stroke_raises_pump_pressure_at_full_command_and_slows_lowering():
    cmds = commands([(0.5, 2.0, 100.0), (3.0, 4.5, -100.0)], 5.0)
    nominal = simulate(cmds, M, seed=None, rod_pos0_m=0.1)
    limited = simulate(cmds, M, faults=[Fault("spool_stroke", 1.0)], seed=None, rod_pos0_m=0.1)
    # A 40 % opening must pass the same pump flow: a larger drop P->A.
    assert at(limited, "PP", 1.5) > at(nominal, "PP", 1.5) + 20.0
    assert at(limited, "SpoolPos", 1.5) == pytest.approx(40.0)
    # Lowering is metered out through A->T: slower with the smaller opening.
    assert abs(at(limited, "RodVel", 4.0)) < 0.9 * abs(at(nominal, "RodVel", 4.0))


def test_spool_wear_leaks_at_centre():
    nominal = simulate(RAISE_HOLD, M, seed=None)
    worn = simulate(RAISE_HOLD, M, faults=[Fault("spool_wear", 1.0)], seed=None)
    # Centred spool: the pump feeds the leak across the lands, and the load drifts.
    assert at(worn, "QP", 7.0) > 1.0 and at(nominal, "QP", 7.0) < 0.05
    drift = abs(at(worn, "RodPosTrue", 7.5) - at(worn, "RodPosTrue", 3.0))
    assert drift > 1.0


def test_fault_onset_and_ramp():
    fault = parse_fault("piston_wear:0.8@10+20")
    assert fault == Fault("piston_wear", 0.8, 10.0, 20.0)
    sev = fault.severity_at(np.array([0.0, 9.99, 10.0, 20.0, 30.0, 100.0]))
    assert np.allclose(sev, [0, 0, 0, 0.4, 0.8, 0.8])
    abrupt = parse_fault("spool_wear:0.5@3")
    assert np.allclose(abrupt.severity_at(np.array([2.99, 3.0])), [0.0, 0.5])
    # Before onset the faulty run equals the nominal run sample for sample.
    cmds = commands([(0.5, 1.5, 60.0), (2.5, 3.5, -60.0)], 6.0)
    nominal = simulate(cmds, M, seed=3)
    late = simulate(cmds, M, faults=[parse_fault("piston_wear:1@4")], seed=3)
    assert np.array_equal(nominal["PA"][:400], late["PA"][:400])
    assert not np.array_equal(nominal["PA"][420:], late["PA"][420:])


@pytest.mark.parametrize(
    "text",
    [
        "nonsense:0.5",
        "piston_wear:1.5",
        "piston_wear:-0.1",
        "piston_wear",
        "spool_wear:x",
        "spool_wear:0.5@-1",
        "spool_wear:0.5@2+-1",
    ],
)
def test_bad_fault_specs_are_refused(text):
    with pytest.raises(ConfigError):
        parse_fault(text)


@pytest.mark.parametrize(
    "text",
    [
        "nonsense",
        "sensor_lag:delay_ms=500",
        "sensor_lag:bogus=1",
        "sensor_lag:delay_ms",
        "cylinder_friction:coulomb_n=900,static_n=500",
        "valve_deadband:overlap_pct=abc",
    ],
)
def test_bad_effect_specs_are_refused(text):
    with pytest.raises(ConfigError):
        parse_effect(text)


def test_entrained_air_slows_the_pressure_rise_at_low_pressure_only():
    air = [Effect.make("entrained_air", air_fraction=0.01)]

    def rise_s(effects, cmds, rod_pos0_m, start_s, lo_bar, hi_bar):
        tr = run_plant(cmds, M, effects=effects, rod_pos0_m=rod_pos0_m, record_period_s=None)
        pa = tr.pa_pa / 1e5
        after = tr.t_s >= start_s
        t_lo = tr.t_s[after][np.argmax(pa[after] >= lo_bar)]
        t_hi = tr.t_s[after][np.argmax(pa[after] >= hi_bar)]
        return t_hi - t_lo

    # Low pressure: lower onto the bottom stop (cap side drains to ~0 bar), then raise.
    low = commands([(0.1, 1.5, -100.0), (2.0, 3.0, 5.0)], 3.0)
    nominal_low = rise_s([], low, 0.1, 2.0, 0.5, 10.0)
    air_low = rise_s(air, low, 0.1, 2.0, 0.5, 10.0)
    assert air_low > 2.0 * nominal_low
    # High pressure: stalled on the top stop, from 100 to 150 bar: the air is compressed away.
    high = commands([(0.1, 3.0, 10.0)], 3.0)
    nominal_high = rise_s([], high, 0.5, 0.0, 100.0, 150.0)
    air_high = rise_s(air, high, 0.5, 0.0, 100.0, 150.0)
    assert air_high == pytest.approx(nominal_high, rel=0.1)


def test_valve_deadband_stops_motion_for_small_commands():
    small = commands([(0.5, 3.0, 8.0)], 3.0)
    nominal = simulate(small, M, seed=None)
    overlapped = simulate(
        small, M, effects=[Effect.make("valve_deadband", overlap_pct=10)], seed=None
    )
    assert at(nominal, "RodVel", 2.0) > 5.0  # mm/s
    assert abs(at(overlapped, "RodVel", 2.0)) < 1e-6
    assert np.ptp(overlapped["RodPosTrue"]) < 1e-3


@pytest.mark.parametrize("delay_ms", [30.0, 70.0])
def test_sensor_lag_shifts_the_cross_correlation_peak(delay_ms):
    from monitor.sim.cycles import make_cycle

    cmds = make_cycle("step", 30.0, seed=2)
    true = simulate(cmds, M, seed=None)
    lagged = simulate(cmds, M, effects=[Effect.make("sensor_lag", delay_ms=delay_ms)], seed=None)
    a = np.diff(true["PA"])
    b = np.diff(lagged["PA"])
    lags = np.arange(-20, 21)
    xc = [np.dot(a[20:-20], np.roll(b, -k)[20:-20]) for k in lags]
    assert abs(lags[int(np.argmax(xc))] - delay_ms / 10.0) <= 1


def test_spool_dynamics_follow_a_second_order_response():
    from scipy.signal import lsim

    cmds = commands([(0.5, 2.0, 60.0)], 2.0)
    rec = simulate(
        cmds,
        M,
        effects=[Effect.make("spool_dynamics", natural_freq_hz=5, damping_ratio=0.7)],
        seed=None,
    )
    # Reference: scipy's LTI simulation of w^2 / (s^2 + 2 zeta w s + w^2), driven by the
    # same linearly interpolated 100 Hz command.
    w = 2 * np.pi * 5
    _, expected, _ = lsim(([w * w], [1.0, 2 * 0.7 * w, w * w]), cmds["SpoolCmd"], cmds.t)
    assert np.abs(rec["SpoolPos"] - expected).max() < 0.05  # % of stroke
    assert at(rec, "SpoolPos", 0.52) < 0.25 * 60.0  # it does lag the command


def test_pump_control_dynamics_lag_the_flow():
    cmds = commands([(0.5, 3.0, 100.0)], 3.0)
    nominal = simulate(cmds, M, seed=None)
    slow = simulate(
        cmds, M, effects=[Effect.make("pump_control_dynamics", time_constant_ms=200)], seed=None
    )
    # From dead-head (displacement 0) the swash plate needs ~tau to come up.
    assert at(nominal, "QP", 0.6) > 20.0
    assert at(slow, "QP", 0.6) < 0.5 * at(nominal, "QP", 0.6)
    assert at(slow, "QP", 2.5) == pytest.approx(at(nominal, "QP", 2.5), abs=0.2)


def test_load_variation_changes_holding_pressure_with_position():
    cmds = commands([], 1.0)
    slope = [Effect.make("load_variation", slope_n_per_mm=10.0)]
    low = simulate(cmds, M, effects=slope, seed=None, rod_pos0_m=0.05)
    high = simulate(cmds, M, effects=slope, seed=None, rod_pos0_m=0.45)
    a_a = np.pi / 4 * 0.063**2
    # 10 N/mm over 400 mm = 4 kN more load, carried by the cap side: + 4000 / A_A.
    assert at(high, "PA", 0.5) - at(low, "PA", 0.5) == pytest.approx(4000 / a_a / 1e5, abs=0.05)


def test_cold_oil_cuts_pump_leakage():
    cmds = commands([(0.5, 3.0, 100.0)], 3.0)  # stalled at the top stop: PP near 200 bar
    visc = [Effect.make("oil_viscosity", pump_leak_lpm_per_100bar=2.0)]
    warm = simulate(
        commands([(0.5, 3.0, 100.0)], 3.0, oil_temp_c=40.0),
        M,
        effects=visc,
        seed=None,
        rod_pos0_m=0.5,
    )
    cold = simulate(
        commands([(0.5, 3.0, 100.0)], 3.0, oil_temp_c=0.0),
        M,
        effects=visc,
        seed=None,
        rod_pos0_m=0.5,
    )
    del cmds
    # Dead-headed, the pump delivers only its leakage: 2 L/min per 100 bar at 40 degC, so
    # the compensator settles where (200 - p)/10 * 24.2 = 2 p / 100 -> about 198.4 bar.
    p = at(warm, "PP", 2.5)
    assert p == pytest.approx(200 * 24.2 / 10 / (24.2 / 10 + 0.02), abs=0.1)
    # Cold oil is far more viscous: laminar leakage falls, PP climbs towards 200 bar.
    assert at(cold, "PP", 2.5) > p + 1.0


def _ring_hz(effects: list[Effect]) -> float:
    """Where the rod rings after a short spool pulse at mid-stroke (the velocity's peak)."""
    cmds = commands([(0.1, 0.13, 10.0)], 1.5)
    tr = run_plant(cmds, M, effects=effects, rod_pos0_m=0.25, record_period_s=None)
    keep = tr.t_s > 0.3
    v = tr.rod_vel_m_s[keep] - tr.rod_vel_m_s[keep].mean()
    n = 16 * len(v)
    return np.fft.rfftfreq(n, tr.t_s[1] - tr.t_s[0])[np.abs(np.fft.rfft(v, n)).argmax()]


def test_hose_compliance_lowers_the_natural_frequency():
    soft = _ring_hz([Effect.make("hose_compliance", wall_modulus_gpa=0.5)])
    assert soft < 0.9 * _ring_hz([])


def _added(line_cm3_bar: float, cylinder_cm3_bar: float) -> Effect:
    return Effect.make(
        "hose_compliance",
        law="added_capacitance",
        line_capacitance_cm3_per_bar=line_cm3_bar,
        cylinder_capacitance_cm3_per_bar=cylinder_cm3_bar,
    )


def test_hoses_as_added_capacitances_match_the_series_modulus_they_stand_for():
    # A wall modulus E adds V/E to each node: 0.5 L / 0.5 GPa = 1e-12 m^3/Pa = 0.1 cm^3/bar
    # on the pump line, 0.3 L / 0.5 GPa = 0.06 cm^3/bar on each cylinder line.
    assert (
        M.line.line_volume_m3 == 0.5e-3
        and M.cylinder.dead_volume_a_m3 == M.cylinder.dead_volume_b_m3 == 0.3e-3
    )
    cmds = commands([(0.5, 1.5, 60.0), (3.0, 3.8, -50.0)], 5.0)
    series = simulate(
        cmds, M, effects=[Effect.make("hose_compliance", wall_modulus_gpa=0.5)], seed=None
    )
    added = simulate(cmds, M, effects=[_added(0.1, 0.06)], seed=None)
    for sig in ("PP", "PA", "PB", "QP", "RodPosTrue"):
        assert np.allclose(added[sig], series[sig], rtol=1e-9, atol=1e-9), sig
    nominal = simulate(cmds, M, seed=None)
    assert np.abs(series["PA"] - nominal["PA"]).max() > 1.0  # the hoses do show in PA


def test_only_the_cylinder_lines_capacitance_softens_the_closed_cylinder():
    # Spool pulsed, then closed: the rod rings against its chambers' oil alone, so a hose
    # on the pump line leaves that ring where it was and one on the cylinder lines lowers
    # it.  By hand at the rod's 0.25 m: chamber volumes 1.079 and 0.825 L, oil capacitances
    # V/beta 0.0720 and 0.0550 cm^3/bar; stiffness A^2/C summed over the chambers falls to
    # 0.520 of itself with 0.06 cm^3/bar more on each, so the frequency falls to
    # sqrt(0.520) = 0.721 (and to 0.985 with the 0.002 cm^3/bar left on them).
    bare = _ring_hz([])
    assert _ring_hz([_added(0.1, 0.002)]) / bare == pytest.approx(0.985, abs=0.02)
    assert _ring_hz([_added(0.002, 0.06)]) / bare == pytest.approx(0.721, abs=0.03)


def test_cylinder_friction_needs_more_pressure_to_move():
    cmds = commands([(0.5, 3.0, 15.0)], 3.0)
    nominal = simulate(cmds, M, seed=None)
    rough = simulate(
        cmds,
        M,
        effects=[Effect.make("cylinder_friction", coulomb_n=1500, static_n=2000)],
        seed=None,
    )
    a_a = np.pi / 4 * 0.063**2
    a_b = np.pi / 4 * (0.063**2 - 0.036**2)

    def force(rec):
        return (at(rec, "PA", 2.0) * a_a - at(rec, "PB", 2.0) * a_b) * 1e5

    assert force(rough) - force(nominal) == pytest.approx(1500, rel=0.1)


@pytest.mark.parametrize("name", list(CATALOGUE))
def test_every_effect_is_off_by_default_and_changes_a_duty_cycle(name):
    from monitor.sim.cycles import make_cycle

    cmds = make_cycle("boom", 20.0, seed=5)
    nominal = simulate(cmds, M, seed=None)
    changed = simulate(cmds, M, effects=[Effect.make(name)], seed=None)
    diff = max(np.abs(changed[s] - nominal[s]).max() for s in ("PP", "PA", "PB", "QP"))
    assert diff > 0.5


def test_random_commands_never_give_negative_or_nan_pressures():
    rng = np.random.default_rng(11)
    t = np.arange(3001) * 0.01
    spool = np.repeat(rng.uniform(-100, 100, 301), 10)[: len(t)]
    from monitor.io.recording import Recording

    cmds = Recording(
        t,
        {
            "SpoolCmd": spool,
            "PumpDispCmd": np.repeat(rng.uniform(0, 100, 301), 10)[: len(t)],
            "EngineSpeed": np.repeat(rng.uniform(0, 2500, 301), 10)[: len(t)],
            "OilTemp": np.full_like(t, -20.0),
        },
    )
    effects = [Effect.make(n) for n in CATALOGUE]
    faults = [Fault("piston_wear", 1.0), Fault("spool_wear", 1.0), Fault("spool_stroke", 0.5)]
    for machine in (M, M.with_changes(compensator_enabled=False)):
        for fx, ff in (((), ()), (effects, faults)):
            trace = run_plant(cmds, machine, ff, fx, record_period_s=None)
            for p in (trace.pp_pa, trace.pa_pa, trace.pb_pa):
                assert np.all(np.isfinite(p)) and p.min() >= 0.0
            assert trace.rod_pos_m.min() >= 0.0 and trace.rod_pos_m.max() <= 0.5
