"""The third plant's physics checked by hand (benchmarks/gap_third, written apart).

python -m pytest -q benchmarks/test_bench_gap_third.py
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from benchmarks.gap_third import generate, machine, plant, scenario, sensors
from benchmarks.gap_third.plant import BAR, IX

FS = 100


def _inputs(n_s: float, spool: float, t_on: float = 1.0, temp: float = 40.0) -> dict:
    n = int(n_s * FS)
    sp = np.zeros(n)
    sp[int(t_on * FS) :] = spool
    return {
        "spool": sp,
        "disp": np.ones(n),
        "n_set": np.full(n, 2200.0),
        "temp": np.full(n, temp),
        "ripple": np.zeros(n),
    }


def _run(prm: np.ndarray, inputs: dict, x0: float = 0.1) -> np.ndarray:
    s = scenario.initial_state(prm)
    s[4] = x0
    s[1] = plant.load_force(prm, x0) / prm[IX["area_a"]]
    s[0] = 195 * BAR
    s[8] = 0.5
    return plant.run(
        prm,
        s,
        inputs["spool"],
        inputs["disp"],
        inputs["n_set"],
        inputs["temp"],
        inputs["ripple"],
        scenario.DT_S,
    )


@pytest.fixture(scope="module")
def nominal() -> np.ndarray:
    return machine.nominal()


def test_reference_load_at_mid_stroke(nominal):
    """6 kN gravity and 400 kg equivalent mass at mid stroke; within 2.5 % along the stroke."""
    assert plant.load_force(nominal, 0.25) == pytest.approx(6000.0, rel=1e-9)
    h, _ = plant.boom_geometry(nominal, 0.25)
    assert nominal[IX["inertia"]] / h**2 == pytest.approx(400.0)
    forces = [plant.load_force(nominal, x) for x in np.linspace(0, 0.5, 21)]
    assert max(forces) / min(forces) < 1.03


def test_steady_speed_is_pump_flow_over_cap_area(nominal):
    """Full spool, pump at full displacement: v = QP / A_A, QP = D n / 60 less the slip."""
    out = _run(nominal, _inputs(2.5, 1.0, t_on=0.2))
    k = slice(1500, 2000)  # 1.5-2.0 s, rod well inside the stroke
    v, q = out[k, 5].mean(), out[k, 3].mean()
    assert out[k, 4].min() > 0.05 and out[k, 4].max() < 0.45
    assert v == pytest.approx(q / nominal[IX["area_a"]], rel=0.01)
    q_th = nominal[IX["d_max"]] * out[k, 8].mean() / 60  # compensator open: full stroke
    slip = nominal[IX["pump_slip40"]] * out[k, 0].mean()
    assert q == pytest.approx(q_th - slip, rel=0.005)
    assert v == pytest.approx(0.1294, rel=0.03)  # 11 cm^3 x 2200 rpm / cap area, less droop


def test_centred_spool_holds_the_load(nominal):
    """Spool closed at mid stroke: PA A_A - PB A_B carries the gravity load, rod stays."""
    out = _run(nominal, _inputs(5.0, 0.0), x0=0.25)
    end = out[-500:]
    force = end[:, 1] * nominal[IX["area_a"]] - end[:, 2] * nominal[IX["area_b"]]
    assert force.mean() == pytest.approx(plant.load_force(nominal, 0.25), rel=0.01)
    assert abs(end[-1, 4] - 0.25) < 1e-3


def test_relief_caps_pump_pressure(nominal):
    """No compensator, spool closed: relief flow = pump flow, PP = crack + 10 bar x Q/Qmax."""
    prm = nominal.copy()
    prm[IX["p_comp_start"]], prm[IX["p_comp_full"]] = 300 * BAR, 310 * BAR
    out = _run(prm, _inputs(3.0, 0.0))
    pp = out[-500:, 0].mean()
    q = out[-500:, 3].mean()
    expected = 210 * BAR + 10 * BAR * q / prm[IX["q_max"]]
    assert pp == pytest.approx(expected, abs=0.3 * BAR)
    assert 218 * BAR < pp < 220.5 * BAR
    # with the compensator the pump destrokes between 190 and 200 bar
    out = _run(nominal, _inputs(3.0, 0.0))
    assert 190 * BAR < out[-500:, 0].mean() < 200 * BAR


def _effect(name: str, seed: int = 3, rodpos: bool = True) -> tuple[np.ndarray, dict, dict]:
    prm = machine.nominal()
    key, sens = machine.apply_effect(name, prm, np.random.default_rng(seed), rodpos)
    return prm, key, sens


def test_deadband_stops_small_commands(nominal):
    prm, key, _ = _effect("valve_deadband")
    cmd = 0.5 * key["overlap_pct"] / 100
    moved = _run(nominal, _inputs(2.0, cmd))[-1, 4] - 0.1
    still = _run(prm, _inputs(2.0, cmd))[-1, 4] - 0.1
    assert moved > 0.005 and abs(still) < 5e-4


def test_slow_spool_lags_its_command(nominal):
    prm, _, _ = _effect("spool_dynamics")

    def rise_ms(p: np.ndarray) -> float:
        out = _run(p, _inputs(1.5, 0.8))
        return float(np.argmax(out[:, 6] > 0.8 * 0.63)) - 1000.0

    # nominal: the solenoid's 40 strokes/s slew takes 0.504 / 40 = 12.6 ms to 63 %
    assert 12 <= rise_ms(nominal) < 16 and rise_ms(prm) > 40


def test_slow_pump_control_delays_flow(nominal):
    prm, _, _ = _effect("pump_control_dynamics")

    def t90_ms(p: np.ndarray) -> float:
        out = _run(p, _inputs(2.0, 1.0))
        q = out[1000:, 3]
        return float(np.argmax(q > 0.9 * q[-200:].mean()))

    assert t90_ms(prm) > t90_ms(nominal) + 30


def test_air_and_hoses_soften_the_oil(nominal):
    """Capacity of a 0.3 L chamber at 10 bar by hand: air (isothermal) and hoses add to it."""
    temp, p, vol = 40.0, 10 * BAR, 0.3e-3
    beta_oil = nominal[IX["beta0"]] + 8.0 * (p - 100 * BAR)
    base = plant._capacity(nominal, vol, p, temp)
    hose0 = nominal[IX["hose_cap"]] / (1 + p / nominal[IX["hose_p"]])
    assert base == pytest.approx(vol / beta_oil + hose0, rel=1e-9)
    prm, key, _ = _effect("entrained_air")
    a0, p_abs = key["air_fraction_at_atm"], p + plant.P_ATM
    va = a0 * plant.P_ATM / p_abs
    frac = va / (1 - a0 + va)
    by_hand = vol * ((1 - frac) / beta_oil + frac / p_abs) + hose0
    assert plant._capacity(prm, vol, p, temp) == pytest.approx(by_hand, rel=1e-9)
    assert by_hand > 1.5 * base
    prm, key, _ = _effect("hose_compliance")
    assert plant._capacity(prm, vol, p, temp) > 2 * base


def test_friction_raises_the_lifting_pressure(nominal):
    """A steady raise needs about Fc / A_A more in A with a LuGre friction (Fc at speed)."""
    prm, key, _ = _effect("cylinder_friction")
    k = slice(1500, 1900)
    pa0 = _run(nominal, _inputs(2.2, 0.5, t_on=0.2))[k, 1].mean()
    out = _run(prm, _inputs(2.2, 0.5, t_on=0.2))
    pa1, v = out[k, 1].mean(), out[k, 5].mean()
    assert v > 3 * key["stribeck_velocity_mm_s"] / 1e3  # sliding: friction is Coulomb
    assert pa1 - pa0 == pytest.approx(key["coulomb_n"] / nominal[IX["area_a"]], rel=0.15)


def test_viscosity_leak_follows_temperature_and_wear_does_not():
    for name, follows in (("oil_viscosity", True), ("worn_pump", False)):
        prm, key, _ = _effect(name)
        assert key.get("follows_viscosity") is follows
        leak = {}
        for temp in (20.0, 60.0):
            out = _run(prm, _inputs(1.0, 0.0, temp=temp))
            d = prm[IX["d_max"]] * out[-1, 8] / 60 * out[-1, 7]
            leak[temp] = (d - out[-1, 3]) / out[-1, 0]
        ratio = leak[60.0] / leak[20.0]
        by_hand = plant.viscosity_ratio(20.0) / plant.viscosity_ratio(60.0)
        assert ratio == pytest.approx(by_hand if follows else 1.0, rel=0.02)


def test_load_variation_slope_matches_its_key():
    prm, key, _ = _effect("load_variation")
    dx = 0.01
    slope = (plant.load_force(prm, 0.25 + dx) - plant.load_force(prm, 0.25 - dx)) / (2e3 * dx)
    assert slope == pytest.approx(key["slope_n_per_mm"], rel=0.05)
    assert abs(slope) > 2.0  # N/mm: well beyond the base boom's own variation
    assert abs(machine.slope_n_per_mm(machine.nominal())) < 1.0  # the bare boom: 0.7


def _read(states: np.ndarray, inputs: dict, sens: dict, effect: str) -> dict:
    return sensors.read(states, inputs, sens, effect, True, np.random.default_rng(5))


def test_sensor_lag_delays_the_reading_by_its_delay(nominal):
    """Cross-correlation of the lagged and prompt PA readings peaks at the delay."""
    inputs = _inputs(6.0, 0.0)
    inputs["spool"][100:] = 0.6 * np.sign(np.sin(np.arange(500) / 40.0))
    states = _run(nominal, inputs)
    sens = {
        "delay_ms": 40.0,
        "time_constant_ms": 0.0,
        "update_ms": 1.0,
        "signals": ["PP", "PA", "PB", "QP"],
    }
    prompt = _read(states, inputs, sens, "none")
    late = _read(states, inputs, sens, "sensor_lag")
    a, b = np.diff(prompt["PA"]), np.diff(late["PA"])
    lags = np.arange(0, 10)
    xc = [np.dot(a[: len(a) - k], b[k:]) for k in lags]
    assert lags[int(np.argmax(xc))] == 4  # 40 ms at 10 ms rows
    np.testing.assert_array_equal(prompt["RodPos"], late["RodPos"])


def test_sensor_calibration_moves_one_column(nominal):
    inputs = _inputs(3.0, 0.5)
    states = _run(nominal, inputs)
    sens = {"signal": "PB", "gain": 1.1, "offset": 5.0}
    plain = _read(states, inputs, {}, "none")
    cal = _read(states, inputs, sens, "sensor_calibration")
    for col in ("PP", "PA", "QP", "RodPos", "EngineSpeed"):
        np.testing.assert_array_equal(plain[col], cal[col])
    inside = (plain["PB"] > 1) & (cal["PB"] < 399)
    diff = (cal["PB"] - plain["PB"])[inside]
    # same noise in both: what differs is 0.1 x (reading - its noise) + 5 bar, to a step
    assert np.abs(diff - (0.1 * plain["PB"][inside] + 5.0)).max() < 0.25


def test_answer_key_round_trips(tmp_path):
    """generate writes a key whose entries rebuild the same recordings bit for bit."""
    assert (
        generate.main(
            [
                str(tmp_path),
                "--seed",
                "7",
                "--set",
                "small",
                "--duration",
                "60",
                "--only",
                "sensor_calibration,worn_pump",
            ]
        )
        == 0
    )
    key = json.loads((tmp_path / "key.json").read_text())
    assert key["seed"] == 7 and not key["blind"]
    names = [r["effect"] for r in key["recordings"]]
    assert names == ["sensor_calibration", "worn_pump"]
    for entry in key["recordings"]:
        sc = scenario.Scenario(
            **{
                k: entry[k]
                for k in ("name", "seed", "effect", "tolerance", "rodpos", "warmup", "duration_s")
            }
        )
        again = tmp_path / "again.csv"
        assert json.loads(json.dumps(scenario.record(sc, again))) == entry
        assert again.read_bytes() == (tmp_path / f"{entry['name']}.csv").read_bytes()
    worn = key["recordings"][1]
    assert worn["expected"] == "unexplained" and worn["mechanism"] == "leakage"
    assert worn["warmup"] is True


def test_pump_settings_set_low_move_the_dead_head_pressure(nominal):
    """Spool closed: PP sits in the compensator band, shifted by its key; a low relief caps it."""
    prm, key, _ = _effect("compensator_low")
    pp = _run(prm, _inputs(3.0, 0.0))[-500:, 0].mean() / BAR
    assert 190 + key["shift_bar"] < pp < 200 + key["shift_bar"]
    prm, key, _ = _effect("relief_low")
    pp = _run(prm, _inputs(3.0, 0.0))[-500:, 0].mean() / BAR
    assert key["relief_crack_bar"] < pp < key["relief_crack_bar"] + 10


def test_periodic_force_rings_the_held_load_at_its_frequency(nominal):
    prm, key, _ = _effect("periodic_force")
    out = _run(prm, _inputs(8.0, 0.0), x0=0.25)
    pa = np.polynomial.polynomial.polyfit(np.arange(6000), out[2000:, 1], 2)
    pa = out[2000:, 1] - np.polynomial.polynomial.polyval(np.arange(6000), pa)  # slow drift
    freqs = np.fft.rfftfreq(len(pa), 1e-3)
    spectrum = np.where(freqs > 0.5, np.abs(np.fft.rfft(pa)), 0.0)
    peak = freqs[np.argmax(spectrum)]
    assert peak == pytest.approx(key["frequency_hz"], abs=1 / 6)


def test_scorer_counts_by_the_rules(tmp_path):
    """Cached diagnoses scored: top-1, the sensor's signal, the mechanism first."""
    from benchmarks.gap_third import score

    def entry(name, effect, expected, mechanism=None, signal=None):
        return {
            "name": name,
            "effect": effect,
            "tolerance": 0.03,
            "rodpos": True,
            "expected": expected,
            "mechanism": mechanism,
            "signal": signal,
        }

    recs = [
        entry("a", "valve_deadband", "valve_deadband"),
        entry("b", "sensor_calibration", "sensor_calibration", signal="PB"),
        entry("c", "worn_pump", "unexplained", mechanism="leakage"),
        entry("d", "none", "none"),
        entry("e", "sensor_lag", "sensor_lag"),
    ]
    reps = {
        "a": {"verdict": "valve_deadband"},
        "b": {
            "verdict": "sensor_calibration",
            "params": {"sensor_calibration": {"PA_gain": 1.1, "PA_offset_bar": 0}},
        },
        "c": {"verdict": "unexplained", "suggestion": [{"term": "leakage"}]},
        "d": {"verdict": "oil_viscosity"},
        "e": {"verdict": "hose_compliance"},
    }
    (tmp_path / "gap").mkdir()
    for name, rep in reps.items():
        (tmp_path / "gap" / f"{name}.json").write_text(json.dumps(rep))
    (tmp_path / "key.json").write_text(
        json.dumps({"seed": 1, "blind": False, "set": "small", "recordings": recs})
    )
    assert score.main([str(tmp_path), "--json", str(tmp_path / "s.json")]) == 0
    s = json.loads((tmp_path / "s.json").read_text())["summary"]
    assert s["single_top1"] == [2, 3]  # the sensor error counts as named, its signal does not
    assert s["sensor_right_signal"] == [0, 1]
    assert s["out_of_catalogue"] == [1, 1] and s["healthy_none"] == [0, 1]
    assert s["families"]["sensor_lag @3%"] == [0, 1]
    key = json.loads((tmp_path / "key.json").read_text())
    (tmp_path / "key.json").write_text(json.dumps({**key, "seed": 4242, "blind": True}))
    with pytest.raises(SystemExit):  # a blind seed is not scored by accident
        score.main([str(tmp_path), "--json", str(tmp_path / "s.json")])
