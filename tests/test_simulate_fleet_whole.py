"""`monitor simulate-fleet --machine excavator4`: a fleet of whole machines in the fleet
layout, its answer key, and `monitor fleet run` refusing to judge it as one loop (or a
one-loop log as a whole machine)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from monitor.cli import main
from monitor.config.settings import load_config
from monitor.fleet.simulate import FleetPlan
from monitor.fleet.simulate_whole import TOLERANCED, simulate_whole_fleet, toleranced
from monitor.io.csvio import write_csv
from monitor.offline.loopsniff import loops_in
from monitor.offline.recordings import loop_recordings
from monitor.resources import resource_path
from monitor.sim.cycles import make_cycle
from monitor.sim.machine import load_machine
from monitor.sim.simulate import simulate
from monitor.sim.whole.cycles import make_whole_cycle
from monitor.sim.whole.faults import MachineFault
from monitor.sim.whole.params import load_whole_machine
from monitor.sim.whole.simulate import simulate_whole

PLAN = FleetPlan(machines=5, days=1, logs_per_day=2, log_s=10.0, commissioning_s=10.0)


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    out = tmp_path_factory.mktemp("whole") / "F"
    key = simulate_whole_fleet(out, PLAN, say=lambda _m: None)
    return out, key


def test_the_fleet_is_laid_out_as_the_contract_says(fleet):
    out, key = fleet
    # 5 machines, each with 1 commissioning log and 1 day x 2 logs: 10 logs.
    assert sorted(p.name for p in out.iterdir()) == [
        "M01",
        "M02",
        "M03",
        "M04",
        "M05",
        "answer_key.json",
    ]
    assert len(list(out.glob("*/logs/*.log"))) == 10
    assert len(list(out.glob("*/commissioning/*.log"))) == 5
    for mid in ("M01", "M05"):
        assert [p.name for p in (out / mid / "commissioning").iterdir()] == ["normal.log"]
        assert sorted(p.name for p in (out / mid / "logs").iterdir()) == [
            "day01-1.log",
            "day01-2.log",
        ]
    assert json.loads((out / "answer_key.json").read_text()) == key
    assert key["machine"] == "excavator4"


def test_four_machines_wear_one_loop_each_from_0_to_wear_max_and_the_fifth_is_healthy(fleet):
    _, key = fleet
    roles = {mid: m["role"] for mid, m in key["machines"].items()}
    assert roles == {
        "M01": "stick.piston_wear",
        "M02": "bucket.spool_wear",
        "M03": "swing.motor_leakage",
        "M04": "pump.pump_wear",
        "M05": "healthy",
    }
    for mid, m in key["machines"].items():
        sev = [d["severity"] for d in m["days"]]
        faults = [d["fault"] for d in m["days"]]
        if mid == "M05":
            assert sev == [0.0, 0.0] and faults == [None, None]
        else:  # linear from 0 in the first log to wear_max (0.6) in the last of two
            assert sev == [0.0, 0.6] and faults == [None, roles[mid]]
        for f, k in m["factors"].items():
            assert f in TOLERANCED
            assert 0.95 <= k <= 1.05
        assert {d["cycle"] for d in m["days"]} <= {"mixed", "truck-loading", "lifting"}


def test_a_log_is_the_whole_machine_the_key_names(fleet):
    out, key = fleet
    m = key["machines"]["M01"]
    day = m["days"][-1]  # the stick's piston seal at 0.6
    machine = toleranced(load_whole_machine(), m["factors"], "M01")
    commands = make_whole_cycle(day["cycle"], PLAN.log_s, day["seed"], machine)
    commands.columns["OilTemp"] = np.full(len(commands), day["oil_temp_c"])
    fault = MachineFault("piston_wear", 0.6, loop="stick")
    expected = simulate_whole(commands, machine, [fault], seed=day["seed"])
    cfg = load_config(resource_path("config", "excavator4.yaml"))
    loops = loop_recordings(out / day["log"], cfg, ["boom", "stick", "bucket", "swing"])
    for name, prefix in (("boom", ""), ("stick", "Stick_"), ("swing", "Swing_")):
        rec = loops[name]
        n = min(len(rec), len(expected))
        assert n >= len(expected) - 1
        for signal in ("PP", "PA", "PB", "QP"):
            # through the DBC's 0.01 bar and L/min
            np.testing.assert_allclose(
                rec[signal][:n], expected[prefix + signal][:n], atol=0.005 + 1e-9
            )


def test_fleet_run_refuses_whole_machines_under_a_one_loop_config_in_one_line(
    fleet, tmp_path, capsys
):
    out, _ = fleet
    results = tmp_path / "R"
    assert main(["fleet", "run", str(out), "--out", str(results)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert err[0].startswith("monitor fleet: error: M01/commissioning/normal.log: a whole-machine")
    assert "stick, bucket, swing loops' signals" in err[0]
    assert "the config declares one loop" in err[0] and "config/excavator4.yaml" in err[0]
    assert not results.exists()


def test_a_config_of_several_loops_refuses_model_and_one_loop_logs_in_one_line(
    fleet, tmp_path, capsys
):
    out, _ = fleet
    results = tmp_path / "R"
    config = str(resource_path("config", "excavator4.yaml"))
    run = ["fleet", "run", "--out", str(results), "--config", config]
    model = str(resource_path("config", "boom_excavator4.model.npz"))
    assert main([*run, str(out), "--model", model]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "the config declares 4 loops (boom, stick, bucket, swing)" in err[0]
    assert err[0].startswith(f"monitor fleet: error: --model {model}: ")
    one = tmp_path / "F" / "M09" / "logs"
    one.mkdir(parents=True)
    rec = simulate(make_cycle("boom", 3.0, 1), load_machine(), seed=1)
    from monitor.codec.logwrite import write_candump

    write_candump(one / "day01.log", rec)
    assert main([*run, str(tmp_path / "F")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert err[0].startswith("monitor fleet: error: M09/logs/day01.log: a log of one loop")
    assert "none of the stick, bucket, swing loops' signals" in err[0]
    assert not results.exists()


def test_a_boom_loop_log_is_not_a_whole_machine_and_a_stick_column_is(tmp_path):
    from monitor.codec.logwrite import write_candump

    rec = simulate(make_cycle("boom", 3.0, 1), load_machine(), seed=1)
    write_candump(tmp_path / "boom.log", rec)
    write_csv(tmp_path / "boom.csv", rec)
    assert loops_in(tmp_path / "boom.log") == []
    assert loops_in(tmp_path / "boom.csv") == []
    rec.columns["Swing_PA"] = rec["PA"]
    rec.columns["Stick_QP"] = rec["QP"]
    write_csv(tmp_path / "two.csv", rec)
    assert loops_in(tmp_path / "two.csv") == ["stick", "swing"]


def test_machine_must_be_a_known_whole_machine(tmp_path, capsys):
    args = ["simulate-fleet", str(tmp_path / "F"), "--machines", "1", "--days", "1"]
    assert main([*args, "--machine", "excavator9"]) == 2
    assert "invalid choice: 'excavator9'" in capsys.readouterr().err
    assert not (tmp_path / "F").exists()
