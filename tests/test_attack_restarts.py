"""Restarts mid-operation (issue 43): ``monitor run`` killed (SIGKILL) and started again at
random moments while healthy operation is replayed on the bus from another process.  At
no restart may a sensor fault, a MON_Alarm State 2 or a DM1 with a DTC go out: a start
mid-operation is warming until every signal has been seen (the 1 Hz OilTemp up to a second
later), and the first frame of each message has nothing to break the counter's sequence.

The suite kills it 3 times; ``MONITOR_RESTARTS=20`` kills it 20 times (the issue's count,
about 4 minutes)."""

from __future__ import annotations

import os
import random
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from attack_support import AttackRig, multicast_error
from j1939_support import DM1_ID, decode_dm, reassemble

from monitor.codec.frames import FrameCodec
from monitor.codec.j1939.dtc import PGN_DM1
from monitor.live.outputs import ALARM
from monitor.resources import resource_path

pytestmark = pytest.mark.skipif(multicast_error() is not None, reason=str(multicast_error()))

LOG = resource_path("replay", "normal.log")  # 90 s of healthy operation
RESTARTS = int(os.environ.get("MONITOR_RESTARTS", "3"))


def test_random_restarts_mid_operation_send_no_sensor_fault_nor_dm1(tmp_path: Path) -> None:
    rig = AttackRig(tmp_path, extra="j1939: {enabled: true}\n", time_scale=1.0)
    done = threading.Event()

    def operate() -> None:  # the sensor ECUs: healthy operation until the restarts are done
        while not done.is_set():
            replay = subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "monitor",
                    "replay",
                    str(LOG),
                    "--bus",
                    rig.group,
                    "--interface",
                    "udp_multicast",
                ],
                env=rig.env,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
            while replay.poll() is None and not done.wait(0.2):
                pass
            if replay.poll() is None:
                replay.terminate()
                replay.wait(60)

    rig.sniff()
    ecus = threading.Thread(target=operate, daemon=True)
    rnd = random.Random(43)
    kills = []
    try:
        ecus.start()
        time.sleep(3.0)  # operation under way before the first start
        for _ in range(RESTARTS):
            rig.start()
            pause = rnd.uniform(0.2, 4.0)  # a random moment after it reports monitoring
            time.sleep(pause)
            rig.kill()
            kills.append(pause)
        rig.start()
        time.sleep(3.0)
        assert rig.stop() == 0
    finally:
        done.set()
        if rig.daemon is not None and rig.daemon.poll() is None:
            rig.kill()
        frames = rig.sniffed()
        ecus.join(120)
    assert len(kills) == RESTARTS and rig.starts == RESTARTS + 1
    events = rig.events()
    states = [e["state"] for e in events if e.get("kind") != "bus"]
    codec = FrameCodec.from_dbc()
    alarm_id = codec.message(ALARM).frame_id
    alarm_states = [
        d.values["State"]
        for d in (codec.decode_message(m) for m in frames if m.arbitration_id == alarm_id)
        if d.values is not None
    ]
    dm1 = [
        decode_dm(g["data"])[1]
        for g in reassemble(m for m in frames if m.arbitration_id == DM1_ID)
        if g["pgn"] == PGN_DM1
    ]
    print(  # the counts the report gives (pytest -s)
        f"restarts {RESTARTS}: {len(events)} events {sorted(set(states))}, "
        f"{len(alarm_states)} MON_Alarm frames, states {sorted(set(alarm_states))}, "
        f"{len(dm1)} DM1, with a DTC {sum(d != [(0, 0, 0)] for d in dm1)}"
    )
    assert "sensor_fault" not in states and "fault" not in states, events
    assert alarm_states and 2 not in alarm_states and 1 not in alarm_states
    assert dm1 and all(d == [(0, 0, 0)] for d in dm1)  # no DTC active, ever


def test_a_silent_bus_is_engine_off_never_a_sensor_fault(tmp_path: Path) -> None:
    """The knife-edge behind the restarts' and the soak's stray sensor faults, offline:
    EngineSpeed's frames 3 ms after the others (as a replayer sends them), the row grid
    between them, the whole bus silent for a second: the sensors did not fail, the bus
    went quiet, so the state goes to inactive (engine_off) without a sensor fault first."""
    from monitor.config.settings import load_config
    from monitor.detection.offline import detect
    from monitor.model.modelfile import load_model
    from monitor.sampling.read import read_recording

    lines = LOG.read_text().splitlines()
    t0 = float(lines[0][1 : lines[0].index(")")])
    out = []
    for x in lines:
        t, rest = float(x[1 : x.index(")")]), x[x.index(")") :]
        if t == t0 and "0CFF1203#" not in x:
            continue  # the log starts with EngineSpeed's frame: the row grid at +3 ms
        t += 0.003 if "0CFF1203#" in x else 0.0
        if not 30.0 <= t - t0 < 31.0:  # the whole bus silent for a second
            out.append((t, f"({t:.6f}{rest}"))
    log = tmp_path / "silent.log"
    log.write_text("".join(f"{x}\n" for _, x in sorted(out, key=lambda p: p[0])))
    cfg = load_config()
    det = detect(
        load_model(cfg.model), read_recording(log), cfg.alarm, cfg.horizon, gating=cfg.gating
    )
    states = [(e["state"], e["op_state"]) for e in det.events]
    assert states == [("normal", "normal"), ("inactive", "engine_off"), ("normal", "normal")]
