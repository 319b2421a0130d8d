"""Sensor range checks with field tolerances: a healthy 4-20 mA transducer sits up to
+-0.5 % of full scale off zero and its noise crosses zero, so PA reading -1.5 bar and QP
-0.5 L/min at rest is no sensor fault and no DM1; a sensor reading 20 bar below zero, or
pinned at full scale, still is.  Offline (``monitor detect`` of a CSV) and on the bus (the
daemon on a virtual bus, a DBC whose transducer signals are signed, as some ECUs send
them)."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest
from j1939_support import DM1_ID, TP_CM_ID, TP_DT_ID, decode_dm, reassemble
from live_support import live_config, replay_settled, run_daemon

from monitor.cli import main
from monitor.codec.frames import FrameCodec
from monitor.codec.j1939.dtc import PGN_DM1
from monitor.codec.logwrite import write_candump
from monitor.config.settings import load_config
from monitor.detection.offline import detect
from monitor.detection.plausibility_config import PlausibilityConfig, RangeCheck
from monitor.errors import ConfigError
from monitor.io.csvio import read_csv, write_csv
from monitor.io.recording import Recording
from monitor.resources import resource_path
from monitor.sim.cycles import make_cycle
from monitor.sim.machine import load_machine
from monitor.sim.simulate import simulate

CFG = load_config()
REST_S = 40.0
J1939_IDS = {DM1_ID, TP_CM_ID, TP_DT_ID}


@pytest.fixture(scope="module")
def simulated_csv(tmp_path_factory) -> Path:
    """What `monitor simulate --duration 60 --seed 7 --out run.csv` writes, behind a 40 s
    engine-off rest with the boom on the ground (every line at tank, sensor noise; the flow
    meter and PP, PB read zero or above, as the simulator's do)."""
    run = simulate(make_cycle("boom", 60.0, 7), load_machine(), seed=7)
    n = int(REST_S / 0.01)
    rng = np.random.default_rng(7)
    rest = {
        "SpoolCmd": np.zeros(n),
        "PumpDispCmd": np.full(n, 100.0),
        "EngineSpeed": np.zeros(n),
        "OilTemp": np.full(n, run["OilTemp"][0]),
        "PP": np.abs(rng.normal(0.0, 0.3, n)),
        "PA": rng.normal(0.0, 0.3, n),  # noise crosses zero
        "PB": np.abs(rng.normal(0.0, 0.3, n)),
        "QP": np.abs(rng.normal(0.0, 0.1, n)),
    }
    cols = {k: np.concatenate([rest[k], run[k]]) for k in rest}
    t = np.arange(len(cols["PP"])) * 0.01
    path = tmp_path_factory.mktemp("field") / "run.csv"
    write_csv(path, Recording(t, cols, "simulated"))
    return path


def shifted(src: Path, out: Path, **edits) -> Recording:
    """``src`` with columns edited by hand (``name=f(column, t)``), written to ``out``."""
    rec = read_csv(src)
    cols = {k: v.copy() for k, v in rec.columns.items()}
    for name, f in edits.items():
        cols[name] = f(cols[name], rec.t)
    edited = Recording(rec.t, cols, out.stem)
    write_csv(out, edited)
    return edited


def healthy_offsets(src: Path, out: Path) -> Recording:
    # Transducer offsets within +-0.5 % FS plus noise: PA 2 bar, QP 0.3 L/min below zero
    # at most from the offset; noise on top.
    return shifted(src, out, PA=lambda v, t: v - 1.5, QP=lambda v, t: v - 0.5)


def pa_below_zero(src: Path, out: Path) -> Recording:
    # PA reading 20 bar below zero from 20 s into the rest on (a broken transducer, its
    # current below the 4 mA of zero bar), with the noise of the line it reads.
    return shifted(src, out, PA=lambda v, t: np.where(t >= 20.0, -20.0 + 0.3 * np.sin(t), v))


def pp_pinned(src: Path, out: Path) -> Recording:
    # PP pinned at full scale (400 bar) from 50 s on, while the machine works.
    return shifted(src, out, PP=lambda v, t: np.where(t >= REST_S + 10.0, 400.0, v))


def test_healthy_transducer_offsets_are_no_sensor_fault_offline(
    simulated_csv, tmp_path, model, capsys
) -> None:
    rec = healthy_offsets(simulated_csv, tmp_path / "offsets.csv")
    at_rest = rec.t < REST_S
    # The recording shows what the field shows: PA and QP below zero at rest.
    assert rec["PA"][at_rest].min() < -1.5
    assert rec["QP"][at_rest].min() == pytest.approx(-0.5, abs=0.01)
    det = detect(model, rec, CFG.alarm, CFG.horizon, gating=CFG.gating)
    assert det.summary["sensor_fault"] is False
    assert det.summary["sensor_checks"] == []
    assert all(e["state"] != "sensor_fault" for e in det.events)
    code = main(
        [
            "detect",
            str(tmp_path / "offsets.csv"),
            "--j-every",
            "0",
            "--events",
            str(tmp_path / "events.jsonl"),
        ]
    )
    line = capsys.readouterr().err
    assert "no hydraulic fault (" in line and "signal_range" not in line, line
    assert code == 0


@pytest.mark.parametrize(
    "edit, sensor, first_s",
    [(pa_below_zero, "PA", 20.0 + 0.09), (pp_pinned, "PP", REST_S + 10.0 + 0.09)],
    ids=["PA-20bar", "PP-pinned-400"],
)
def test_real_range_faults_are_still_named_offline(
    simulated_csv, tmp_path, model, edit, sensor, first_s
) -> None:
    rec = edit(simulated_csv, tmp_path / "bad.csv")
    det = detect(model, rec, CFG.alarm, CFG.horizon, gating=CFG.gating)
    checks = {(c["sensor"], c["check"]) for c in det.summary["sensor_checks"]}
    assert (sensor, "signal_range") in checks
    first = next(e for e in det.events if e["sensor_check"] == "signal_range")
    assert first["sensor"] == sensor
    # range_s = 0.1 s: the 10th sample out of range (PA's fault starts at rest: the
    # finding is named at once, the state shows it when the engine runs).
    if sensor == "PP":
        assert first["t"] == pytest.approx(first_s, abs=0.011)
        assert first["state"] == "sensor_fault"


def test_tolerance_is_configured_and_validated(tmp_path) -> None:
    # 1 % of 0..400 bar is 4 bar; of 0..60 L/min 0.6 L/min; 0 switches the tolerance off.
    lo, hi = PlausibilityConfig().range_limits()
    cols = list(CFG.gating.plausibility.limits()[0])
    assert len(cols) == 8
    assert lo[4:].tolist() == pytest.approx([-4.0, -4.0, -4.0, -0.6])
    assert hi[4:].tolist() == pytest.approx([400.0, 400.0, 400.0, 60.0])
    assert all(hi[4:] < [400.0, 400.0, 400.0, 60.0])  # full scale itself is pinned
    assert lo[:4].tolist() == [-100.0, 0.0, 0.0, -40.0]  # commands, engine, oil: exact
    assert hi[:4].tolist() == [100.0, 100.0, 3000.0, 150.0]
    assert PlausibilityConfig(RangeCheck(range_tolerance_fs=0.0)).range_limits()[0][5] == 0.0
    bad = tmp_path / "bad.yaml"
    bad.write_text("plausibility:\n  range_tolerance_fs: 1.0\n")
    with pytest.raises(ConfigError, match=re.escape("plausibility.range_tolerance_fs")):
        load_config(bad)
    shipped = resource_path("config", "monitor.yaml").read_text()
    assert re.search(r"^  range_tolerance_fs: 0\.01\b", shipped, re.M)


# -- the daemon path ----------------------------------------------------------------------


def signed_dbc(tmp: Path) -> Path:
    """The shipped DBC with PP/PA/PB and QP signed (-50..400 bar, -10..60 L/min), as an ECU
    that passes a transducer's reading below zero on sends them; the plausibility ranges
    stay the sensors' 0..400 bar and 0..60 L/min."""
    text = resource_path("dbc", "monitor.dbc").read_text()
    for s in ("PP", "PA", "PB"):
        text, k = re.subn(
            rf"SG_ {s} : (\d+)\|16@1\+ \(0\.01,0\) \[0\|400\]",
            rf"SG_ {s} : \1|16@1- (0.02,0) [-50|400]",
            text,
        )
        assert k == 1
    text, k = re.subn(
        r"SG_ QP : 0\|16@1\+ \(0\.01,0\) \[0\|60\]", "SG_ QP : 0|16@1- (0.01,0) [-10|60]", text
    )
    assert k == 1
    path = tmp / "signed.dbc"
    path.write_text(text)
    return path


def on_the_bus(tmp: Path, rec: Recording) -> tuple[list[dict], list]:
    """The daemon (shipped config but the signed DBC) fed ``rec`` as a candump log: its
    events and the DTCs of every DM1 it sent."""
    dbc = signed_dbc(tmp)
    cfg = dataclasses.replace(live_config(tmp), dbc=dbc)
    log = tmp / "run.log"
    write_candump(log, rec, FrameCodec.from_dbc(dbc))
    _, events, frames, _ = run_daemon(cfg, replay_settled(log))
    groups = [
        g
        for g in reassemble([m for m in frames if m.arbitration_id in J1939_IDS])
        if g["pgn"] == PGN_DM1
    ]
    dtcs = [decode_dm(g["data"])[1] for g in groups]
    return events, dtcs


def test_healthy_transducer_offsets_are_no_sensor_fault_and_no_dm1_on_the_bus(
    simulated_csv, tmp_path
) -> None:
    rec = healthy_offsets(simulated_csv, tmp_path / "offsets.csv")
    events, dtcs = on_the_bus(tmp_path, rec)
    assert events and all(e["state"] != "sensor_fault" for e in events)
    assert {e["sensor_check"] for e in events} == {None}
    assert dtcs and all(d == [(0, 0, 0)] for d in dtcs)  # "no DTC" every second


@pytest.mark.parametrize(
    "edit, sensor", [(pa_below_zero, "PA"), (pp_pinned, "PP")], ids=["PA-20bar", "PP-pinned-400"]
)
def test_real_range_faults_raise_a_sensor_fault_and_dm1_on_the_bus(
    simulated_csv, tmp_path, edit, sensor
) -> None:
    rec = edit(simulated_csv, tmp_path / "bad.csv")
    events, dtcs = on_the_bus(tmp_path, rec)
    named = [e for e in events if e["sensor_check"] == "signal_range"]
    assert named and {e["sensor"] for e in named} == {sensor}
    assert any(e["state"] == "sensor_fault" for e in named)
    # The sensor's proprietary SPN (520192 + 16 + its place among the contract signals:
    # PP 4, PA 5) with FMI 2, data erratic (docs/reference/j1939.md).
    spn = 520192 + 16 + {"PP": 4, "PA": 5}[sensor]
    faults = [d for d in dtcs if d != [(0, 0, 0)]]
    assert faults, "no DM1 with a DTC"
    assert {(s, fmi) for d in faults for (s, fmi, _) in d} == {(spn, 2)}
