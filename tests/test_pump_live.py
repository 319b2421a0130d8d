"""The pump rule in the daemon and at the desk on one whole-machine log with a worn pump:
the daemon's pump lines equal `monitor detect --pump`'s, its MON_Alarm_Pump frames follow
them, and the machine's finding names the pump."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from live_support import live_config, run_daemon, settle

from monitor.bus.replay import replay_log
from monitor.cli import main
from monitor.codec.frames import FrameCodec
from monitor.resources import resource_path

CONFIG = resource_path("config", "excavator4.yaml")
ONSET_S = 20.0
KEYS = ("t", "time", "state", "fault", "margin_residual_bar", "threshold_bar", "counted_s")


@pytest.fixture(scope="module")
def worn(tmp_path_factory) -> Path:
    """A development seed of the pump's benchmark, the pump worn at full severity."""
    log = tmp_path_factory.mktemp("pump") / "worn.log"
    argv = ["simulate", "--machine", "excavator4", "--seed", "501", "--duration", "110"]
    argv += ["--fault", f"pump.pump_wear:1@{ONSET_S:g}", "--out", str(log)]
    assert main(argv) == 0
    return log


@pytest.fixture(scope="module")
def run(tmp_path_factory, worn) -> dict[str, Any]:
    cfg = live_config(tmp_path_factory.mktemp("pump-live"), CONFIG)

    def feed(sender, daemon):  # four loops' frames: slow to take under a loaded CPU
        counts = replay_log(worn, sender, speed=None)
        settle(daemon, counts.sent, timeout_s=900.0)
        return counts

    daemon, events, frames, counts = run_daemon(cfg, feed)
    return {"cfg": cfg, "events": events, "frames": frames, "t0": counts.first_ts}


def test_live_pump_lines_equal_detect_pump(run, worn, tmp_path) -> None:
    out = tmp_path / "pump.jsonl"
    argv = ["detect", str(worn), "--config", str(CONFIG), "--pump", "--events", str(out)]
    assert main(argv) == 0
    offline = [json.loads(x) for x in out.read_text().splitlines()]
    live = [e for e in run["events"] if e.get("loop") == "pump"]
    assert [[e[k] for k in KEYS] for e in live] == [[e[k] for k in KEYS] for e in offline]
    faults = [e for e in live if e["state"] == "fault"]
    assert faults and faults[0]["t"] > ONSET_S and faults[0]["fault"] == "pump_wear"


def test_the_pump_alarm_frame_follows_the_pump_lines(run) -> None:
    codec = FrameCodec.from_dbc(run["cfg"].dbc)
    fid = codec.message("MON_Alarm_Pump").frame_id
    states = []
    for m in run["frames"]:
        if m.arbitration_id == fid:
            d = codec.decode_message(m)
            assert d.ok, d.rejection
            states.append((d.values["State"], d.values["Fault"], d.values["MarginResidual"]))
    raised = next(e for e in run["events"] if e.get("loop") == "pump" and e["state"] == "fault")
    assert (1, 1) in [(s, f) for s, f, _ in states]  # fault, pump_wear
    first = next(r for s, f, r in states if s == 1)
    assert first == pytest.approx(raised["margin_residual_bar"], abs=0.001)


def test_the_machine_finding_names_the_pump_and_no_loop(run) -> None:
    findings = [e for e in run["events"] if e.get("kind") == "finding"]
    assert findings and findings[-1]["named"] == "pump"
    # A loop alarm on the worn pump would be explained by it, never named on its own.
    assert all(f["named"] in ("pump", None) for f in findings), findings
