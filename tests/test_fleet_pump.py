"""`monitor fleet run` on whole machines with the config's `pump:`: the pump commissioned per
machine (its own margin law, the support rule), judged on every log as a row `loop: pump`,
and the machine's finding in the tables and pages naming the pump when its rule is in fault."""

from __future__ import annotations

import json
import subprocess
import sys

import pyarrow.parquet as pq
import pytest

from monitor.fleet.loops import machine_verdict
from monitor.fleet.simulate import FleetPlan
from monitor.fleet.simulate_whole import simulate_whole_fleet
from monitor.fleet.store import ResultStore
from monitor.resources import resource_path
from tests.fleet_support import env

CONFIG = str(resource_path("config", "excavator4.yaml"))


def _row(log: str, loop: str, verdict: str, t: float | None = None, **kw) -> dict:
    return {
        "machine": log.split("/")[0],
        "log": log,
        "loop": loop,
        "sha256": "ab",
        "verdict": verdict,
        "alarm": verdict == "fault",
        "first_alarm_t": t,
        "error": None,
        "model": "commissioned",
        "reference_model": False,
        **kw,
    }


def test_the_tables_carry_the_machine_s_finding_by_the_daemon_s_rule(tmp_path):
    store = ResultStore(tmp_path)
    # M01: the boom alarmed at 130 s, the pump at 150 s on a window that began at 100 s:
    # the margin was off the law before the boom's alarm, so the pump names and the boom's
    # alarm is explained by it.  The stick, healthy, has no part.
    worn = "M01/logs/day02.log"
    store.add(_row(worn, "boom", "fault", 130.0, max_level=1.6), [])
    store.add(_row(worn, "stick", "healthy"), [])
    store.add(_row(worn, "pump", "fault", 150.0, max_level=1.2, alarm_since_t=100.0), [])
    # M02: the stick first (50 s), the bucket at 300 s: the stick names, the bucket is
    # secondary; the pump's rule was off (not judged, with why), never healthy.
    two = "M02/logs/day01.log"
    store.add(_row(two, "stick", "fault", 50.0, max_level=1.1), [])
    store.add(_row(two, "bucket", "fault", 300.0, max_level=4.0), [])
    store.add(_row(two, "pump", "not_judged", not_judged_why="its threshold rests on 3"), [])
    # M03: healthy everywhere, no finding.
    store.add(_row("M03/logs/day01.log", "boom", "healthy"), [])
    store.add(_row("M03/logs/day01.log", "pump", "healthy"), [])
    store.compact()
    table = pq.read_table(tmp_path / "logs.parquet")
    # The columns of whole-machine fleets before, in their order, then the new ones.
    names = table.column_names
    assert names[names.index("loop") :] == [
        "loop",
        "not_judged_why",
        "alarm_since_t",
        "finding",
        "finding_role",
    ]
    got = {(r["log"], r["loop"]): (r["finding"], r["finding_role"]) for r in table.to_pylist()}
    assert got == {
        (worn, "boom"): ("pump", "explained_by_pump"),
        (worn, "stick"): ("pump", None),
        (worn, "pump"): ("pump", "named"),
        (two, "stick"): ("stick", "named"),
        (two, "bucket"): ("stick", "secondary"),
        (two, "pump"): ("stick", None),
        ("M03/logs/day01.log", "boom"): (None, None),
        ("M03/logs/day01.log", "pump"): (None, None),
    }
    rows = table.to_pylist()
    v1 = machine_verdict("M01", [r for r in rows if r["machine"] == "M01"])
    assert v1.text == "FAULT: pump (also alarmed: boom)"
    v2 = machine_verdict("M02", [r for r in rows if r["machine"] == "M02"])
    assert v2.text == "FAULT: stick (also alarmed: bucket); not judged: pump"
    # A pump alarm on a window that began after the boom's alarm: the boom came first and
    # is not explained (secondary), the pump still names (its rule in fault).
    late = tmp_path / "late"
    store = ResultStore(late)
    store.add(_row(worn, "boom", "fault", 90.0, max_level=1.6), [])
    store.add(_row(worn, "pump", "fault", 150.0, max_level=1.2, alarm_since_t=100.0), [])
    store.compact()
    roles = {r["loop"]: r["finding_role"] for r in pq.read_table(late / "logs.parquet").to_pylist()}
    assert roles == {"boom": "secondary", "pump": "named"}


@pytest.fixture(scope="module")
def pump_fleet(tmp_path_factory):
    """One whole machine whose pump the simulator wears (pump_wear, severity 0 on its first
    log, 0.6 on its second), a 900 s commissioning run (the pump's support rule needs 8
    independent windows) and two 240 s logs: one machine keeps the fixture's four loop
    fits to what the pump needs; its first log is the healthy pump."""
    where = tmp_path_factory.mktemp("pump")
    fleet = where / "F"
    plan = FleetPlan(machines=1, days=1, logs_per_day=2, log_s=240.0, commissioning_s=900.0)
    key = simulate_whole_fleet(fleet, plan, say=lambda _m: None, roles=(("pump", "pump_wear"),))
    results = where / "R"
    cmd = [sys.executable, "-m", "monitor", "fleet", "run", str(fleet), "--out", str(results)]
    proc = subprocess.run(
        [*cmd, "--config", CONFIG, "--workers", "1"], capture_output=True, text=True, env=env()
    )
    assert proc.returncode == 0, proc.stderr
    return fleet, results, key


def test_a_worn_pump_is_named_and_a_healthy_one_is_not(pump_fleet, tmp_path):
    fleet, results, key = pump_fleet
    assert [d["fault"] for d in key["machines"]["M01"]["days"]] == [None, "pump.pump_wear"]
    rows = {(r["log"], r["loop"]): r for r in pq.read_table(results / "logs.parquet").to_pylist()}
    pump = {log: r for (log, loop), r in rows.items() if loop == "pump"}
    assert sorted(pump) == sorted(d["log"] for m in key["machines"].values() for d in m["days"])
    # Every pump judged with its own machine's law (the support rule let 900 s through).
    for r in pump.values():
        assert r["model"] == "commissioned" and r["verdict"] != "not_judged", r
    worn = "M01/logs/day01-2.log"
    assert pump[worn]["verdict"] == "fault" and pump[worn]["fault"] == "pump_wear"
    assert [log for log, r in pump.items() if r["alarm"]] == [worn]
    # The machine's finding on the worn log names the pump on each of its rows.
    assert {r["finding"] for (log, _), r in rows.items() if log == worn} == {"pump"}
    assert {r["finding"] for (log, _), r in rows.items() if log != worn} <= {None, "bucket"}
    model = json.loads((results / "models" / "M01.pump.json").read_text())
    assert model["trained"]["machine_id"] == "M01" and model["threshold_bar"] > 0
    out = tmp_path / "md"
    web = tmp_path / "web"
    cmd = [sys.executable, "-m", "monitor", "fleet", "report", str(results), "--out", str(out)]
    proc = subprocess.run(
        [*cmd, "--html", str(web), "--fleet", str(fleet), "--config", CONFIG],
        capture_output=True,
        text=True,
        env=env(),
    )
    assert proc.returncode == 0, proc.stderr
    page = (out / "fleet.md").read_text()
    line = next(x for x in page.splitlines() if x.startswith(f"| M01 | {worn} |"))
    assert line.split(" | ")[2].startswith("FAULT: pump")
    assert line.rstrip(" |").endswith("fault")  # the pump's cell, last
    assert "| M01 pump |" in page
    index = (web / "index.html").read_text()
    assert "FAULT: pump" in index
    assert "pump_wear" in (web / "machine-M01-pump.html").read_text()
