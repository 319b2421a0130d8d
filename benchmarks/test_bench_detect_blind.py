"""The outsider's detection plant (benchmarks/detect_blind) against hand calculations."""

from __future__ import annotations

import numpy as np
import pytest

from benchmarks.detect_blind import plant, records, sensors
from benchmarks.detect_blind.params import BAR, IDX, NOMINAL, nominal, viscosity_cst

A_CAP = np.pi / 4 * 0.063**2
A_ANN = A_CAP - np.pi / 4 * 0.036**2


def run(p, seconds, spool, x0=0.25, temp=40.0, fault="normal", sev=0.0, payload=1.0):
    n = int(seconds / plant.SAMPLE_S)
    s = plant.initial_state(p, x0, payload)
    lever = np.full(n, spool, dtype=float)
    out = plant.simulate(
        p,
        s,
        0.0,
        lever,
        np.ones(n),
        np.full(n, 2200.0),
        np.full(n, temp),
        np.full(n, sev),
        fault,
        payload,
    )
    return out


def test_oil_viscosity_follows_the_grade():
    p = nominal()
    assert viscosity_cst(40.0, p[IDX["nu40_cst"]], p[IDX["nu100_cst"]]) == pytest.approx(46.0)
    assert viscosity_cst(100.0, p[IDX["nu40_cst"]], p[IDX["nu100_cst"]]) == pytest.approx(6.8)
    assert viscosity_cst(25.0, 46.0, 6.8) > 80.0  # VG46 near 90 cSt at 25 degC


def test_steady_extension_speed_is_pump_flow_over_cap_area():
    p = nominal()
    p[IDX["pump_leak_m3_spa"]] = 0.0
    p[IDX["valve_leak_m3_spa"]] = 0.0
    out = run(p, 2.5, 1.0, x0=0.05)
    q_pump = 11e-6 * 2200 / 60  # the pump is far from its compensator: full displacement
    v = out[150:250, plant.V].mean()  # 1 s of steady travel (the pump ripple averages out)
    assert out[-1, plant.X] < 0.49  # still travelling
    assert v == pytest.approx(q_pump / A_CAP, rel=0.005)
    assert out[150:250, plant.PP].max() < 190 * BAR


def test_held_load_stays_with_closed_centre_and_no_leakage():
    p = nominal()
    p[IDX["valve_leak_m3_spa"]] = 0.0
    out = run(p, 20.0, 0.0, x0=0.25)
    assert np.ptp(out[:, plant.X]) < 1e-5  # 0.01 mm in 20 s
    force = out[-1, plant.PA] * A_CAP - out[-1, plant.PB] * A_ANN
    assert force == pytest.approx(NOMINAL["gravity_n"] * plant.gravity_shape(0.5), abs=300.0)


def test_piston_wear_lets_the_held_boom_sink_and_the_pressures_meet():
    p = nominal()
    p[IDX["valve_leak_m3_spa"]] = 0.0
    out = run(p, 20.0, 0.0, x0=0.25, fault="piston_wear", sev=0.5)
    assert out[-1, plant.X] < 0.25 - 1e-3
    # Cap and rod side joined: they meet where p * rod area carries the load.
    assert out[-1, plant.PA] - out[-1, plant.PB] < 2 * BAR


@pytest.mark.parametrize("sev", [0.1, 0.3, 0.6])
def test_piston_leak_flow_is_coefficient_times_pressure_difference(sev):
    p = nominal()
    p[IDX["valve_leak_m3_spa"]] = 0.0
    s = plant.initial_state(p, 0.25, 1.0)
    s[plant.PA], s[plant.PB], s[plant.V] = 100 * BAR, 20 * BAR, 0.0
    d = np.empty(plant.N_STATE)
    plant.derivatives(p, s, 0.0, 1.0, 2200.0, 1.0, plant.PISTON_WEAR, sev, 1.0, 0.0, d)
    beta_a = 1 / (1 / 1.5e9 + 0.004 * 1e5 / (101e5) ** 2)
    leak = -d[plant.PA] * (0.3e-3 + A_CAP * 0.25) / beta_a
    assert leak == pytest.approx(6e-12 * sev * 80 * BAR, rel=1e-6)


def test_spool_wear_leaks_at_centre_and_not_beyond_its_band():
    p = nominal()
    p[IDX["valve_leak_m3_spa"]] = 0.0
    dpl = NOMINAL["dp_lam_pa"]
    q_pa, q_at, q_pb, q_bt = plant.valve_flows(
        p, 0.0, 200 * BAR, 100 * BAR, 20 * BAR, 1.0, plant.SPOOL_WEAR, 0.5
    )
    by_hand = 20 / 60000 * 0.04 * np.sqrt(100 / 10)  # 4 % of a full edge at 100 bar
    assert q_pa == pytest.approx(by_hand, rel=1e-3)
    assert q_pa > 0 and q_at > 0 and q_pb > 0 and q_bt > 0
    healthy = plant.valve_flows(p, 0.0, 200 * BAR, 100 * BAR, 1 * BAR, 1.0, plant.NONE, 0.0)
    assert healthy == (0.0, 0.0, 0.0, 0.0)
    worn = plant.valve_flows(p, 0.3, 200 * BAR, 100 * BAR, 1 * BAR, 1.0, plant.SPOOL_WEAR, 0.5)
    assert worn[1] == 0.0 and worn[2] == 0.0  # the closed edges beyond 25 % stroke: tight
    assert dpl < 10 * BAR


def test_spool_stroke_stops_the_spool_short():
    p = nominal()
    out = run(p, 1.0, 1.0, x0=0.05, fault="spool_stroke", sev=0.4)
    assert out[-1, plant.U] == pytest.approx(1 - 0.5 * 0.4)
    assert out[:, plant.U].max() <= 0.8 + 1e-12


def test_relief_limits_pressure_where_it_passes_the_pump_flow():
    p = nominal()
    p[IDX["pump_leak_m3_spa"]] = 0.0
    p[IDX["comp_crack_pa"]], p[IDX["comp_full_pa"]] = 300 * BAR, 310 * BAR  # compensator off
    out = run(p, 6.0, 1.0, x0=0.45)  # into the end stop at full lever
    assert out[-1, plant.X] > 0.5
    # Linear relief: full flow (the pump's at 2200 rpm) at its full-flow pressure.
    assert out[-100:, plant.PP].mean() == pytest.approx(220 * BAR, abs=0.5 * BAR)


def test_compensator_holds_the_pump_below_relief():
    p = nominal()
    out = run(p, 6.0, 1.0, x0=0.45)
    pp = out[-100:, plant.PP].mean()
    assert 190 * BAR < pp < 200 * BAR


def test_transducer_offset_gain_and_quantisation_as_drawn():
    rng = np.random.default_rng(7)
    tr = sensors.Transducer(400.0, 0.0, 0.004, 1.003)
    value = np.linspace(0.0, 390.0, 2001)
    got = tr.read(value, rng)
    lsb_bar = sensors.ADC_LSB_MA / 16.0 * 400.0  # 12 bits over 0-25 mA: 0.153 bar
    assert lsb_bar == pytest.approx(0.1526, abs=1e-4)
    assert np.abs(got - (1.003 * value + 0.004 * 400.0)).max() <= lsb_bar / 2 + 1e-9
    steps = np.unique(np.round(np.diff(np.unique(got)) / lsb_bar, 6))
    assert set(steps) <= {1.0, 2.0}
    # Below zero the loop current saturates at 3.8 mA: -5 bar on a 400 bar transducer.
    assert tr.read(np.array([-50.0]), rng)[0] == pytest.approx(-5.0, abs=lsb_bar)


def test_drawn_transducers_stay_within_half_a_percent_and_noise_as_stated():
    rng = np.random.default_rng(3)
    drawn = [sensors.Transducer.draw(rng, 400.0, 0.3) for _ in range(500)]
    assert max(abs(t.offset_fs) for t in drawn) <= 0.005
    assert max(abs(t.gain - 1) for t in drawn) <= 0.005
    noise = drawn[0].read(np.full(20000, 100.0), rng)
    assert noise.std() == pytest.approx(np.hypot(0.3, 0.1526 / np.sqrt(12)), rel=0.05)


def test_a_recording_has_the_contract_columns_and_oil_temperature_at_1_hz(tmp_path):
    m = records.Machine.draw("M", 0.05, 1)
    rows = records.record(m, records.RunSpec(30.0, "mixed", 30.0, 32.0, seed=2))
    assert rows.shape == (3000, 10)
    temp = rows[:, 4]
    changes = np.flatnonzero(np.diff(temp)) + 1
    assert np.all(changes % 100 == 0)  # OilTemp only moves on whole seconds
    path = tmp_path / "r.csv"
    records.write_csv(path, rows)
    assert path.read_text().splitlines()[0] == ",".join(records.COLUMNS)


@pytest.mark.parametrize("k", [0, 1, 3, 10])
def test_poisson_upper_bound_matches_the_chi_square_form(k):
    from scipy.stats import chi2

    from benchmarks.detect_blind.metrics import poisson_upper, rate_per_hour

    assert poisson_upper(k) == pytest.approx(chi2.ppf(0.95, 2 * k + 2) / 2, rel=1e-9)
    assert rate_per_hour(0, 20.0)["upper95_per_h"] == pytest.approx(-np.log(0.05) / 20.0)


def test_an_alarm_before_the_onset_is_early_not_a_detection():
    from benchmarks.detect_blind.metrics import detection

    def row(t, named):
        return {
            "alarm": t is not None,
            "first_alarm_t": t,
            "onset_s": 100.0,
            "fault": "spool_wear",
            "fault_named": named,
        }

    d = detection(
        [
            row(130.0, "spool_wear"),
            row(50.0, "spool_wear"),
            row(None, None),
            row(190.0, "piston_wear"),
        ]
    )
    assert (d["runs"], d["detected"], d["early_alarms"], d["isolated"]) == (4, 2, 1, 1)
    assert d["median_delay_s"] == pytest.approx(60.0)


def test_seeds_give_the_same_plan_and_different_seeds_differ():
    from benchmarks.detect_blind.generate import Scale, fleet_plan, type_plan

    scale = Scale(normal_hours=0.5)
    a, b, c = type_plan(1, scale), type_plan(1, scale), type_plan(2, scale)
    assert [x[3] for x in a] == [x[3] for x in b]
    assert [x[3] for x in a] != [x[3] for x in c]
    assert np.array_equal(a[0][1].params, b[0][1].params)
    fleet = fleet_plan(1, scale)
    machines = {x[1].name for x in fleet}
    commissioned = {x[1].name for x in fleet if x[2] == "commissioning"}
    assert len(machines) == 6 and len(commissioned) == 5
    wear = [x[3].severity for x in fleet if x[2] == "wear"]
    assert max(wear) == pytest.approx(0.6) and min(wear) == 0.0


def test_a_fleet_row_with_an_empty_error_column_is_no_error(tmp_path):
    pd = pytest.importorskip("pandas")
    from benchmarks.detect_blind import report

    key = {
        "files": [
            {"path": "fleet/M01/commissioning/c.csv", "kind": "commissioning", "machine": "M01"},
            {
                "path": "fleet/M01/logs/a.csv",
                "kind": "normal",
                "machine": "M01",
                "fault": None,
                "severity": 0.0,
            },
            {
                "path": "fleet/M01/logs/b.csv",
                "kind": "normal",
                "machine": "M01",
                "fault": None,
                "severity": 0.0,
            },
        ]
    }
    rows = [
        {
            "log": f"M01/logs/{n}.csv",
            "machine": "M01",
            "verdict": v,
            "alarm": False,
            "fault": None,
            "sensor_fault": False,
            "error": e,
        }
        for n, v, e in (("a", "healthy", None), ("b", "error", "unreadable"))
    ]
    pd.DataFrame(rows).to_parquet(tmp_path / "one.parquet")
    pd.DataFrame(rows[:1]).to_parquet(tmp_path / "none.parquet")  # an all-empty column
    both = report.fleet_summary(pd.read_parquet(tmp_path / "one.parquet"), key, 0)
    assert both["healthy_commissioned"]["errors"] == 1
    clean = report.fleet_summary(pd.read_parquet(tmp_path / "none.parquet"), key, 0)
    assert clean["healthy_commissioned"]["errors"] == 0
