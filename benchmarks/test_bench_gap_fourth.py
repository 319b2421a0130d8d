"""The fourth gap plant by hand: its physics against textbook values, each withheld effect
moving the traces its physical way, the key rebuilding its recordings, blind seeds kept."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from benchmarks.gap_fourth import effects, generate, record, score, sensors
from benchmarks.gap_fourth import params as pr
from benchmarks.gap_fourth import plant as pl
from benchmarks.gap_fourth.kernel import OUT_NAMES, integrate

C = {n: i for i, n in enumerate(OUT_NAMES)}


def run(p, lever, disp=1.0, rod0=0.25, temp=45.0, noise=None):
    """The 1 ms trace of a lever profile (fractions, 1 ms apart)."""
    lever = np.asarray(lever, dtype=float)
    d = np.full(lever.size, disp)
    w = np.zeros(lever.size) if noise is None else noise
    trace, _ = integrate(p, pr.initial_state(p, rod0, temp), lever, d, w, 1e-4, 10)
    return trace


def steps(*pieces):
    """A lever profile from (seconds, value) pieces."""
    return np.concatenate([np.full(int(s * 1000), v) for s, v in pieces])


def with_effect(name, **k):
    return effects.apply(name, k, pr.nominal())[0]


@pytest.fixture(scope="module")
def nominal_move():
    """Rest, a full-lever extension from 100 mm, rest again."""
    p = pr.nominal()
    return p, run(p, steps((1.0, 0.0), (1.5, 1.0), (3.0, 0.0)), rod0=0.1)


def test_steady_rod_speed_is_pump_flow_over_cap_area(nominal_move):
    p, tr = nominal_move
    m = slice(1800, 2400)  # steady extension, clear of the stops
    v = tr[m, C["v1"]].mean()
    q = tr[m, C["QP"]].mean()
    assert v == pytest.approx(q / p[pl.A_CAP], rel=2e-3)
    # the pump's geometric flow at the engine's speed less its slip (0.25 L/min/100 bar)
    n = tr[m, C["we"]].mean()
    slip = p[pl.SLIP40] * tr[m, C["PP"]].mean() * 46.0 / record_viscosity(p, 45.0)
    assert q == pytest.approx(p[pl.D_MAX] * n - slip, rel=3e-3)
    assert 0.125 < v < 0.131  # 11 cm^3/rev at 2150-2240 rpm over a 63 mm bore


def record_viscosity(p, temp_c):
    return pl.viscosity_cst(p, temp_c)


def test_centred_spool_holds_the_load(nominal_move):
    p, tr = nominal_move
    hold = tr[3500:, :]
    assert np.ptp(hold[:, C["x1"]]) < 1e-4  # under 0.1 mm in 2 s
    force = hold[-1, C["pA"]] * p[pl.A_CAP] - hold[-1, C["pB"]] * p[pl.A_ROD]
    assert force == pytest.approx(p[pl.F_GRAV], rel=0.01)


def test_pump_settings_compensator_and_relief():
    p = pr.nominal()
    tr = run(p, steps((1.0, 0.0)))
    # spool centred, no flow: the compensator destrokes fully at 200 bar
    assert tr[-200:, C["PP"]].mean() / 1e5 == pytest.approx(200.0, abs=0.6)
    q = p.copy()
    q[pl.PC_START], q[pl.PC_FULL] = 400e5, 410e5  # compensator out of the way
    tr = run(q, steps((1.5, 1.0)), rod0=0.49)  # pushing against the top stop
    flow = tr[-200:, C["QP"]].mean()
    want = 210.0 + 10.0 * flow / q[pl.RELIEF_Q]  # the relief's linear override
    assert tr[-200:, C["PP"]].mean() / 1e5 == pytest.approx(want, abs=0.3)


def test_walther_viscosity_matches_the_reference_oil():
    p = pr.nominal()
    assert pl.viscosity_cst(p, 40.0) == pytest.approx(46.0, rel=1e-9)
    assert pl.viscosity_cst(p, 100.0) == pytest.approx(6.8, rel=1e-9)


def _extend(p, lever=1.0, rod0=0.1, temp=45.0):
    return run(p, steps((0.5, 0.0), (1.2, lever), (1.0, 0.0)), rod0=rod0, temp=temp)


@pytest.fixture(scope="module")
def base_extend():
    return _extend(pr.nominal())


def test_friction_raises_the_pressure_that_moves_the_rod(base_extend):
    p = with_effect(
        "cylinder_friction",
        coulomb_at_100bar_n=800.0,
        zero_pressure_share=0.5,
        breakaway_ratio=1.5,
        stribeck_mm_s=10.0,
    )
    tr = _extend(p)
    m = slice(1200, 1600)
    dpa = (tr[m, C["pA"]] - base_extend[m, C["pA"]]).mean()
    pa = tr[m, C["pA"]].mean()
    f = p[pl.FR_C0] + p[pl.FR_KP] * pa
    assert dpa * p[pl.A_CAP] == pytest.approx(f, rel=0.05)


def test_thin_oil_leaks_more_from_the_pump(base_extend):
    p = with_effect("oil_viscosity", nu40_cst=10.0)
    tr = _extend(p)
    m = slice(1200, 1600)
    # while the pump delivers at ~60 bar its laminar slip grows as the viscosity falls
    ratio = pl.viscosity_cst(pr.nominal(), 45.0) / pl.viscosity_cst(p, 45.0)
    extra = (
        p[pl.SLIP40]
        * tr[m, C["PP"]].mean()
        * (ratio - 1.0)
        * 46.0
        / pl.viscosity_cst(pr.nominal(), 45.0)
    )
    assert (base_extend[m, C["QP"]] - tr[m, C["QP"]]).mean() == pytest.approx(extra, rel=0.1)


def _rise_ms(tr, col, start_ms=500):
    x = tr[start_ms : start_ms + 600, C[col]]
    lo, hi = x[0], x[-100:].mean()
    return int(np.argmax((x - lo) / (hi - lo) > 0.9))


def _ringing_hz(tr):
    """The oil column's ringing after the spool closes on a moving rod (pA, 1.75-2.25 s)."""
    x = tr[1750:2250, C["pA"]]
    i = np.arange(x.size)
    x = x - np.polyval(np.polyfit(i, x, 2), i)
    spec = np.abs(np.fft.rfft(x * np.hanning(x.size), 8192))
    fr = np.fft.rfftfreq(8192, 1e-3)
    return fr[fr > 3][np.argmax(spec[fr > 3])]


def test_oil_column_rings_at_its_natural_frequency(base_extend):
    p = pr.nominal()
    x = base_extend[1750, C["x1"]]
    beta = pl.beta_oil(p, base_extend[1750, C["pA"]])
    va = p[pl.V_DEAD_A] + p[pl.A_CAP] * x
    vb = p[pl.V_DEAD_B] + p[pl.A_ROD] * (p[pl.STROKE] - x)
    k_oil = beta * (p[pl.A_CAP] ** 2 / va + p[pl.A_ROD] ** 2 / vb)
    k = 1.0 / (1.0 / k_oil + 1.0 / p[pl.K_STRUCT])  # the boom's structure in series
    want = math.sqrt(k / (p[pl.M1] + p[pl.M2])) / (2.0 * math.pi)
    assert _ringing_hz(base_extend) == pytest.approx(want, rel=0.1)


def test_air_and_hoses_soften_the_lines(base_extend):
    air = _extend(with_effect("entrained_air", air_share_at_1atm=0.02, dissolve_s=2.0))
    hose = _extend(
        with_effect("hose_compliance", hose_cm3_per_bar=0.2, instant_share=0.6, creep_s=0.3)
    )
    # more oil for the same pressure rise: a softer column rings slower
    base = _ringing_hz(base_extend)
    assert _ringing_hz(air) < 0.92 * base
    assert _ringing_hz(hose) < 0.8 * base


def test_deadband_swallows_a_small_lever():
    small = steps((0.3, 0.0), (1.0, 0.08), (0.2, 0.0))
    moved = np.ptp(run(pr.nominal(), small)[:, C["x1"]])
    held = np.ptp(run(with_effect("valve_deadband", overlap_pct=12.0), small)[:, C["x1"]])
    assert moved > 2e-3 and held < 1e-4


def test_slow_spool_and_slow_pump_are_late(base_extend):
    spool = _extend(with_effect("spool_dynamics", full_stroke_ms=200.0, pilot_ms=40.0))
    assert _rise_ms(spool, "xs") >= 0.9 * 200.0 > _rise_ms(base_extend, "xs") + 100
    pump = _extend(with_effect("pump_control_dynamics", servo_ms=100.0, full_stroke_ms=250.0))
    assert _rise_ms(pump, "QP") > _rise_ms(base_extend, "QP") + 80


def test_pose_dependent_load():
    k = {"boom_angle_mid_rad": 0.4, "angle_span_rad": 1.2}
    p = with_effect("load_variation", **k)
    lo = run(p, steps((1.5, 0.0)), rod0=0.05)
    hi = run(p, steps((1.5, 0.0)), rod0=0.45)
    f = [t[-1, C["pA"]] * p[pl.A_CAP] - t[-1, C["pB"]] * p[pl.A_ROD] for t in (lo, hi)]
    want = effects.load_change_n(k) * 0.8  # 5-95 % of the stroke, nearly linear
    assert f[1] - f[0] == pytest.approx(want, rel=0.03)
    assert want < -1000.0


def test_sensor_lag_delays_the_readings_only():
    e = {"effect": "sensor_lag", "params": {"gateway_delay_ms": 30, "snubber_ms_at_40c": 10.0}}
    p, sens = effects.apply(e["effect"], e["params"], pr.nominal())
    tr = _extend(p)
    out = record.sensed({"trace": tr, "sens": sens, "p": p})
    true = sensors.true_signals(tr)
    d = np.diff(true["PA"])
    r = np.diff(out["PA"])
    lags = range(0, 80)
    best = max(lags, key=lambda k: float(np.dot(d[: d.size - k], r[k:])))
    assert 30 + 5 <= best <= 30 + 20  # the delay plus the snubber's lag (~8 ms at 45 degC)
    assert np.array_equal(out["RodPos"], sensors.first_order(true["RodPos"], 0.002))


def test_sensor_calibration_reads_gain_times_true_plus_offset():
    rng = np.random.default_rng(3)
    x = np.linspace(20.0, 180.0, 20000)
    read = sensors.transmitter(rng, "PA", x, 0.0, 1.1, -5.0)
    fit = np.polyfit(x, read, 1)
    assert fit[0] == pytest.approx(1.1, abs=2e-3) and fit[1] == pytest.approx(-5.0, abs=0.2)


def test_outside_faults_move_their_paths(base_extend):
    rest = steps((2.0, 0.0))
    low = run(with_effect("compensator_low", shift_bar=-35.0), rest)
    assert low[-100:, C["PP"]].mean() / 1e5 == pytest.approx(165.0, abs=0.6)
    worn = _extend(with_effect("worn_pump", leak_lpm_at_200bar=4.0))
    m = slice(1200, 1600)
    pp = worn[m, C["PP"]].mean()
    leak = 4.0 * math.sqrt(pp / 200e5) / 60000.0
    dq = (base_extend[m, C["QP"]] - worn[m, C["QP"]]).mean()
    assert dq == pytest.approx(leak, rel=0.05)
    seal = run(with_effect("piston_seal_bypass", leak_lpm_at_100bar=3.0), rest, rod0=0.25)
    # the loaded cap side leaks into the rod side: the pressures meet and the boom sinks
    assert seal[-1, C["pB"]] > 20e5 and seal[-1, C["x1"]] < 0.25 - 0.003
    relief = run(with_effect("port_relief_leak", leak_lpm_at_100bar=2.0), rest)
    assert relief[-1, C["x1"]] < 0.25 - 0.005  # the cap's oil leaks to tank: the boom sinks
    chip = _extend(with_effect("chip_in_notch", blocked_share=0.4), lever=0.45)
    assert chip[1500, C["v1"]] < 0.8 * _extend(pr.nominal(), lever=0.45)[1500, C["v1"]]
    vib = run(
        with_effect("travel_vibration", amplitude_n=800.0, frequency_hz=2.0, phase_rad=0.0), rest
    )
    pa = vib[1000:, C["pA"]] / 1e5
    spec = np.abs(np.fft.rfft(pa - pa.mean()))
    assert np.argmax(spec) == 2  # 2 Hz over the 1 s window


def test_key_rebuilds_the_same_recordings_bit_for_bit(tmp_path):
    entries = generate.draw(5, "small", 20.0)
    picks = [e for e in entries if e["effect"] in ("sensor_lag", "sensor_calibration")]
    again = json.loads(json.dumps(picks))
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    for e, f in zip(picks, again, strict=True):
        a = record.build(e, tmp_path / "a").read_bytes()
        b = record.build(f, tmp_path / "b").read_bytes()
        assert a == b and a.startswith(b"t,SpoolCmd,PumpDispCmd,EngineSpeed,OilTemp,PP,PA,PB,QP")
    assert generate.draw(5, "small", 20.0) == entries


def test_blind_seed_refused_without_spend_blind(tmp_path, capsys):
    assert generate.main([str(tmp_path / "g"), "--seed", "1000"]) == 2
    assert not (tmp_path / "g").exists()
    (tmp_path / "s").mkdir()
    (tmp_path / "s" / "key.json").write_text(json.dumps({"seed": 4321, "recordings": []}))
    assert score.main([str(tmp_path / "s"), "--json", str(tmp_path / "x.json")]) == 2
    assert "--spend-blind" in capsys.readouterr().err
    assert not (tmp_path / "x.json").exists()


def test_full_set_counts():
    todo = generate.plan("full")
    assert len(todo) == 60 + 6 + 6
    for e in effects.CATALOGUE:
        for b in generate.BANDS:
            assert todo.count((e, b)) == 3
