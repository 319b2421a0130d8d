"""The daemon on a kernel SocketCAN bus (vcan0) as its own process, with can-utils
(candump, canplayer, cansend, cangen) as independent peers.

Runs where vcan0 exists: a Linux box (``ip link add dev vcan0 type vcan``) or the CI VM
(``.ci/vm/vcan-suite.sh``); skips elsewhere.  Few, coarse scenarios with generous timeouts:
Python in the VM is 25-40x slower than on the host, so logs are replayed ``SLOWER`` times
slower than real time and the daemon's ``bus.time_scale`` maps them back to log seconds
(tests/vcan_support.py).  Times asserted here are log seconds unless named wall.
"""

from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from live_support import REPO, start_daemon, wait_for_text, wait_until, write_config
from vcan_support import (
    CHANNEL,
    SLOWER,
    Capture,
    decode,
    frame_id,
    slowed_copy,
    stop,
    vcan_config,
    vcan_missing,
)  # fmt: skip

from monitor.config import load_config
from monitor.detector import detect
from monitor.io.candump import read_candump
from monitor.model import load_model
from monitor.resources import resource_path
from monitor.sampler import recording_from_candump

pytestmark = [pytest.mark.vcan, pytest.mark.skipif(vcan_missing() is not None,
                                                   reason=str(vcan_missing()))]  # fmt: skip

START_S = 300.0  # wall: a daemon's start (imports, model, numba cache) in a slow VM
FAULT_LOG = resource_path("replay", "spool_wear.log")  # abrupt spool wear at 45 s
ONSET_S = 45.0
SEGMENT = (42.0, 60.0)  # log seconds replayed: the 10 s J window fills before the alarm
STATE = {"normal": 0, "fault": 1, "sensor_fault": 2, "inactive": 3}


@pytest.fixture(scope="module")
def model(tmp_path_factory) -> Path:
    """The small model (tests/vcan_model.sh); CI trains it on the host before the VM."""
    given = os.environ.get("MONITOR_VCAN_MODEL")
    if given:
        return Path(given)
    out = tmp_path_factory.mktemp("model") / "vcan.model.npz"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    subprocess.run(["bash", str(REPO / "tests" / "vcan_model.sh"), str(out)], check=True,
                   env=env, capture_output=True)  # fmt: skip
    return out


def _daemon(tmp: Path, model: Path, name: str) -> tuple[subprocess.Popen, Path]:
    cfg = tmp / "monitor.yaml"
    if not cfg.exists():
        write_config(tmp, vcan_config(tmp, model), model=model)
    log = tmp / f"{name}.log"
    proc = start_daemon(cfg, tmp, log)
    wait_for_text(log, f"monitoring socketcan:{CHANNEL}", proc, START_S)
    return proc, log


def _events(tmp: Path) -> list[dict[str, Any]]:
    path = tmp / "events.jsonl"
    return [json.loads(line) for line in path.read_text().splitlines()] if path.exists() else []


def _replay_s(t_log_s: float) -> float:
    """Wall seconds canplayer needs for ``t_log_s`` of log, with room for a slow VM."""
    return t_log_s * SLOWER * 1.5 + 60.0


# -- 1 and 4: a fault log through canplayer; SIGTERM during the alarm; a restart ------------


@pytest.fixture(scope="module")
def fault_run(tmp_path_factory, model) -> dict[str, Any]:
    tmp = tmp_path_factory.mktemp("fault")
    plain = tmp / "segment.log"  # the segment at its own speed, for the offline reference
    slowed_copy(FAULT_LOG, plain, *SEGMENT, slower=1.0)
    slowed_copy(FAULT_LOG, tmp / "slowed.log", *SEGMENT)
    cfg = load_config(write_config(tmp, vcan_config(tmp, model), model=model))
    offline = detect(load_model(cfg.model), recording_from_candump(plain), cfg.alarm,
                     cfg.horizon)  # fmt: skip
    cap = Capture(tmp / "capture.log")
    first, first_log = _daemon(tmp, model, "daemon1")
    player = subprocess.Popen(["canplayer", "-I", str(tmp / "slowed.log")])
    try:
        wait_until(lambda: any(e["state"] == "fault" for e in _events(tmp)),
                   _replay_s(SEGMENT[1] - SEGMENT[0]))  # fmt: skip
        sigterm_wall = time.time()
        player_running = player.poll() is None  # the faulty data still comes: mid-alarm
        rc_first = stop(first)
        events_at_stop = (tmp / "events.jsonl").read_text()
        second, second_log = _daemon(tmp, model, "daemon2")
        restart_wall = time.time()
        player.wait(_replay_s(SEGMENT[1] - SEGMENT[0]))
        time.sleep(3.0)  # a few heartbeats of the restarted daemon
        rc_second = stop(second)
    finally:
        for p in (player, first, locals().get("second")):
            if p is not None and p.poll() is None:
                p.kill()
        frames = cap.stop()
    return {"tmp": tmp, "offline": offline, "frames": frames, "sigterm_wall": sigterm_wall,
            "restart_wall": restart_wall, "player_running": player_running,
            "rc": (rc_first, rc_second), "events_at_stop": events_at_stop,
            "logs": (first_log.read_text(), second_log.read_text())}  # fmt: skip


def test_alarm_frames_from_the_bus_decode_to_the_fault_after_onset(fault_run) -> None:
    off = fault_run["offline"].summary
    assert off["alarm"] and off["fault"] == "spool_wear"  # the reference itself
    frames = fault_run["frames"]
    sensor_ids = {frame_id(n) for n in ("HYD_Pressures", "HYD_Flow", "HYD_Commands")}
    t0 = next(m.timestamp for m in frames if m.arbitration_id in sensor_ids)
    alarms = decode(frames, "MON_Alarm")
    assert alarms, "no MON_Alarm frame on the bus"
    t_fault, sig = next((t, s) for t, s in alarms if s["State"] == STATE["fault"])
    assert sig["Fault"] == 3  # value table: spool_wear
    assert sig["J"] > sig["Threshold"] > 0
    onset = ONSET_S - SEGMENT[0]
    t_alarm = (t_fault - t0) / SLOWER  # capture time in log seconds from the first frame
    # Never before the data that shows it; late by at most the daemon's lag in a slow VM.
    assert onset < off["first_alarm_t"] - 0.3 <= t_alarm <= off["first_alarm_t"] + 3.0
    # Before the alarm, every MON_Alarm said normal (no hydraulic fault before the onset).
    assert all(s["State"] == STATE["normal"] for t, s in alarms if t < t_fault)
    live = next(e for e in _events(fault_run["tmp"]) if e["state"] == "fault")
    assert live["fault"] == "spool_wear"
    assert abs(live["t"] - off["first_alarm_t"]) <= 0.3  # kernel timestamps, log seconds


def test_status_heartbeat_at_1_hz(fault_run) -> None:
    status = [t for t, _ in decode(fault_run["frames"], "MON_Status")
              if t < fault_run["sigterm_wall"]]  # fmt: skip
    assert len(status) >= 5
    gaps = np.diff(status)
    assert 0.9 <= float(np.median(gaps)) <= 1.3, gaps  # wall clock


def test_sigterm_during_alarm_keeps_every_event_and_a_restart_continues(fault_run) -> None:
    assert fault_run["rc"] == (0, 0)
    assert fault_run["player_running"], "the replay ended before the alarm: not mid-alarm"
    first_log, second_log = fault_run["logs"]
    assert "stopped:" in first_log and "stopped:" in second_log
    at_stop = fault_run["events_at_stop"].splitlines()
    # Every state change the first daemon logged is in the file, flushed before it exited.
    assert len(at_stop) == first_log.count(" s: ")
    assert "fault" in [json.loads(line)["state"] for line in at_stop]
    final = (fault_run["tmp"] / "events.jsonl").read_text().splitlines()
    assert final[: len(at_stop)] == at_stop and len(final) > len(at_stop)  # appended
    after = [t for t, _ in decode(fault_run["frames"], "MON_Status")
             if t > fault_run["restart_wall"]]  # fmt: skip
    assert len(after) >= 2  # the restarted daemon is on the bus


# -- 2: malformed and hostile traffic ---------------------------------------------------


def _cansend(m, data: bytes) -> None:
    ident = f"{m.arbitration_id:08X}" if m.is_extended_id else f"{m.arbitration_id:03X}"
    subprocess.run(["cansend", CHANNEL, f"{ident}#{data.hex()}"], check=True, timeout=60)


def test_malformed_and_flood_traffic_is_counted_and_survived(tmp_path, model) -> None:
    pressures = frame_id("HYD_Pressures")
    valid = [m for m in read_candump(resource_path("replay", "normal.log"))
             if m.arbitration_id == pressures][:20]  # fmt: skip
    cap = Capture(tmp_path / "capture.log")
    daemon, log = _daemon(tmp_path, model, "daemon")
    try:
        for m in valid[:3]:  # wrong DLC: 6 bytes
            _cansend(m, bytes(m.data[:6]))
        for m in valid[3:7]:  # bad checksum: byte 7 off by one
            _cansend(m, bytes(m.data[:7]) + bytes([(m.data[7] + 1) % 256]))
        # Counters: 7 valid frames in order, then one that skips 5 counts.
        for m in valid[7:14] + valid[-1:]:
            _cansend(m, bytes(m.data))
        n_flood = 20000
        t = time.monotonic()
        subprocess.run(["cangen", CHANNEL, "-e", "-I", f"{pressures:08X}", "-L", "8", "-D", "r",
                        "-g", "0", "-n", str(n_flood), "-p", "100"], check=True,
                       timeout=600)  # fmt: skip
        flood_wall = time.monotonic() - t
        print(f"flood: {n_flood} frames in {flood_wall:.2f} s wall "
              f"({n_flood / flood_wall:.0f} frames/s)")  # fmt: skip

        def caught_up() -> bool:  # two heartbeats with the same counters: queue drained
            last = [s for _, s in decode(cap.snapshot(), "MON_Status")][-2:]
            return (
                len(last) == 2
                and last[0]["RxFrames"] == last[1]["RxFrames"]
                and last[0]["RejectedFrames"] == last[1]["RejectedFrames"]
            )

        wait_until(caught_up, 600.0)
        assert daemon.poll() is None, log.read_text()[-3000:]
        rc = stop(daemon)
    finally:
        if daemon.poll() is None:
            daemon.kill()
        frames = cap.stop()
    assert rc == 0
    stopped = next(line for line in log.read_text().splitlines() if "stopped:" in line)
    counts = ast.literal_eval(stopped.split("stopped: ", 1)[1])  # a dict literal
    assert counts["rejected"]["dlc"] == 3  # the flood is all 8-byte frames
    # Random flood data: a CRC passes by chance 1 in 256, so nearly every one is rejected.
    flood_seen = counts["received"] - 3 - 4 - 8
    assert 0 < flood_seen <= n_flood and counts["dropped"] <= flood_seen
    processed = flood_seen - counts["dropped"]
    assert counts["rejected"]["crc"] - 4 >= 0.98 * processed - 5
    assert counts["counter_jumps"] >= 1
    status = decode(frames, "MON_Status")
    last = status[-1][1]
    total = sum(counts["rejected"].values())
    assert last["RejectedFrames"] == total % 65536
    assert last["RxFrames"] == counts["received"] % 65536
    assert last["DroppedFrames"] == counts["dropped"] % 256
    assert all(s["State"] != STATE["fault"] for _, s in decode(frames, "MON_Alarm"))


# -- 3: a sensor that stops -----------------------------------------------------------------


def test_a_sensor_that_stops_is_a_sensor_fault_never_a_hydraulic_one(tmp_path, model) -> None:
    flow = frame_id("HYD_Flow")
    stop_at, end = 4.0, 8.0
    slowed_copy(resource_path("replay", "normal.log"), tmp_path / "slowed.log", 0.0, end,
                drop_id_after=(flow, stop_at))  # fmt: skip
    cap = Capture(tmp_path / "capture.log")
    daemon, log = _daemon(tmp_path, model, "daemon")
    try:
        player = subprocess.run(["canplayer", "-I", str(tmp_path / "slowed.log")],
                                timeout=_replay_s(end))  # fmt: skip
        assert player.returncode == 0
        # The replay has stopped: silence, then the monitor goes inactive (machine off).
        wait_until(lambda: any(e["state"] == "inactive" for e in _events(tmp_path)), 120.0)
        rc = stop(daemon)
    finally:
        if daemon.poll() is None:
            daemon.kill()
        frames = cap.stop()
    assert rc == 0
    states = [e["state"] for e in _events(tmp_path)]
    assert states == ["normal", "sensor_fault", "inactive"], states
    sensor = next(e for e in _events(tmp_path) if e["state"] == "sensor_fault")
    # Stale after 3 cycle times of the 10 ms HYD_Flow frame: right after the stop.
    assert stop_at <= sensor["t"] <= stop_at + 0.3
    alarm_states = [s["State"] for _, s in decode(frames, "MON_Alarm")]
    assert STATE["sensor_fault"] in alarm_states and STATE["fault"] not in alarm_states


# -- 5: monitor replay onto vcan0, recorded by candump ---------------------------------------


def test_replay_onto_vcan0_equals_the_source_frame_for_frame(tmp_path) -> None:
    src = tmp_path / "source.log"
    source = slowed_copy(resource_path("replay", "normal.log"), src, 0.0, 5.0, slower=1.0)
    cap = Capture(tmp_path / "capture.log")
    time.sleep(0.5)  # candump's socket is bound before the first frame
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    done = subprocess.run(
        [sys.executable, "-m", "monitor", "replay", str(src), "--bus", CHANNEL,
         "--interface", "socketcan"],
        env=env, capture_output=True, text=True, timeout=START_S + _replay_s(5.0),
    )  # fmt: skip
    time.sleep(0.5)
    captured = cap.stop()
    assert done.returncode == 0, done.stderr
    key = lambda m: (m.arbitration_id, m.is_extended_id, bytes(m.data))  # noqa: E731
    assert [key(m) for m in captured] == [key(m) for m in source]
