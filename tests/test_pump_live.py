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


def test_a_pump_alarm_raises_its_dm1_at_the_pump_s_address(run) -> None:
    # J1939-21 by hand: priority 6, PGN 65226 (0xFECA, DM1), source address 0xA4 (164,
    # MON_Alarm_Pump's) -> 6 << 26 | 0xFECA << 8 | 0xA4.
    dm1_id = (6 << 26) | (0xFECA << 8) | 0xA4
    assert dm1_id == 0x18FECAA4
    dm1 = [bytes(m.data) for m in run["frames"] if m.arbitration_id == dm1_id]
    assert dm1, "no DM1 from the pump's address"
    # J1939-73 by hand: SPN 520196 (the proprietary range's 520192 + 4) = 0x7F004: its low
    # byte 0x04, then 0xF0, then its top 3 bits (0b111) over FMI 7 (mechanical system not
    # responding) = 0xE7; occurrence count 1, CM 0 -> 0x01.  Lamps: amber on (bits 3-4 of
    # byte 0 = 01 -> 0x04), steady (byte 1: 0xFF, no lamp flashes).
    active = [d for d in dm1 if d[2:6] == bytes((0x04, 0xF0, 0xE7, 0x01))]
    assert active and active[0][:2] == bytes((0x04, 0xFF))
    # Before the pump's alarm, the no-DTC form: lamps off, SPN 0, FMI 0.
    assert dm1[0][:6] == bytes((0x00, 0xFF, 0, 0, 0, 0))
    # No loop's address carries pump_wear's DTC: the loops are not in fault.
    loops = [(6 << 26) | (0xFECA << 8) | sa for sa in (0xA0, 0xA1, 0xA2, 0xA3)]
    assert not [
        m for m in run["frames"] if m.arbitration_id in loops and bytes(m.data)[2:4] == b"\x04\xf0"
    ]


def test_mon_status_carries_the_pump_s_fault(run) -> None:
    codec = FrameCodec.from_dbc(run["cfg"].dbc)
    fid = codec.message("MON_Status").frame_id
    status = []
    for m in run["frames"]:
        if m.arbitration_id == fid:
            d = codec.decode_message(m)
            assert d.ok, d.rejection
            status.append((d.values["PumpFault"], d.values["State"]))
    assert status[0][0] == 0  # the first heartbeat, before any window of the pump's
    # Once the pump rule is in fault MON_Status says so, and its State is fault (1) with it.
    assert (1, 1) in status and all(s == 1 for p, s in status if p == 1)
