"""End to end on a python-can virtual bus: a shipped fault log replayed onto the bus, the
daemon's code path receives it, MON_Alarm frames are read back off the bus.  Timing is
checked in sample-clock (log) time, never wall time."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import can
import pytest
from live_support import assert_same_events, live_config, replay_settled, run_daemon
from naive_frames import recording_from_candump

from monitor.cli import main
from monitor.codec.frames import FrameCodec
from monitor.config.settings import load_config
from monitor.detection.offline import detect
from monitor.io.candump import read_candump
from monitor.live.outputs import ALARM, fault_codes
from monitor.model.modelfile import load_model
from monitor.resources import resource_path

LOG = resource_path("replay", "spool_wear.log")
ONSET_S = 45.0  # replay/regenerate.sh


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> dict[str, Any]:
    tmp = tmp_path_factory.mktemp("e2e")
    cfg = live_config(tmp)
    daemon, live_events, frames, counts = run_daemon(cfg, replay_settled(LOG))
    return {"cfg": cfg, "daemon": daemon, "counts": counts, "frames": frames, "events": live_events}


@pytest.fixture(scope="module")
def offline():
    cfg = load_config()
    return detect(load_model(cfg.model), recording_from_candump(LOG), cfg.alarm, cfg.horizon)


def _alarm_frames(run: dict[str, Any]) -> list[tuple[float, dict[str, float]]]:
    codec = FrameCodec.from_dbc()
    alarm_id = codec.message(ALARM).frame_id
    t0 = run["counts"].first_ts
    out = []
    for m in run["frames"]:
        if m.arbitration_id == alarm_id:
            d = codec.decode_message(m)
            assert d.ok, d.rejection  # valid counter and CRC
            assert not d.counter_jump
            out.append((m.timestamp - t0, d.values))
    return out


def test_alarm_frames_read_back_with_timing_after_onset(run, offline) -> None:
    alarms = _alarm_frames(run)
    assert alarms[0][1]["State"] == 0  # the first tick announces the normal state
    fault = [(t, v) for t, v in alarms if v["State"] == 1]
    assert fault, "no MON_Alarm in fault state on the bus"
    t_first = fault[0][0]
    assert ONSET_S < t_first < ONSET_S + 20.0
    assert t_first == pytest.approx(offline.summary["first_alarm_t"], abs=1e-6)
    assert fault[0][1]["Fault"] == fault_codes(FrameCodec.from_dbc())["spool_wear"]
    # Repeated while in fault at the configured interval, never faster than the cap.
    times = [t for t, _ in alarms]
    gaps = [b - a for a, b in zip(times, times[1:], strict=False)]
    assert min(gaps) >= 1.0 / run["cfg"].outputs.alarm_max_per_s - 1e-6
    repeat = run["cfg"].outputs.alarm_repeat_s
    tail = [t for t, v in fault if v["State"] == 1]
    assert all(
        b - a == pytest.approx(repeat, abs=0.011) for a, b in zip(tail, tail[1:], strict=False)
    )


def test_same_events_as_detect_and_event_log_flushed(run, offline) -> None:
    assert_same_events(run["events"], offline)
    lines = Path(run["cfg"].event_log.path).read_text().splitlines()
    assert [json.loads(x) for x in lines] == run["events"]
    c = run["daemon"].counts()
    assert c["received"] == run["counts"].sent and c["dropped"] == 0
    assert c["ticks"] == len(offline.t)


def test_black_box_spans_before_and_after_the_alarm(run, offline) -> None:
    files = list(Path(run["cfg"].black_box.directory).glob("alarm-*.log"))
    assert len(files) == 1 and "spool_wear" in files[0].name
    stamps = [m.timestamp for m in read_candump(files[0])]
    t_alarm = run["counts"].first_ts + offline.summary["first_alarm_t"]
    assert stamps[0] == pytest.approx(t_alarm - 30.0, abs=0.02)
    log_end = run["counts"].last_ts
    assert stamps[-1] == pytest.approx(min(t_alarm + 10.0, log_end), abs=0.02)


def test_cli_replay_puts_the_log_on_a_virtual_bus() -> None:
    listener = can.Bus(interface="virtual", channel="replay-cli")
    try:
        rc = main(
            ["replay", str(LOG), "--bus", "replay-cli", "--interface", "virtual", "--speed", "1000"]
        )
        n = 0
        while listener.recv(0) is not None:
            n += 1
    finally:
        listener.shutdown()
    assert rc == 0
    assert n == sum(1 for _ in read_candump(LOG))


def test_cli_replay_bad_arguments_exit_2(tmp_path, capsys) -> None:
    assert main(["replay", str(LOG), "--bus", "x", "--interface", "virtual", "--speed", "0"]) == 2
    assert main(["replay", str(tmp_path / "none.log"), "--bus", "x", "--interface", "virtual"]) == 2
    assert "no such file" in capsys.readouterr().err


def test_demo_runs_and_reports_the_alarm(capsys) -> None:
    assert main(["demo", "--speed", "60"]) == 0
    out = capsys.readouterr().out
    assert "state -> FAULT" in out and "isolated: spool_wear" in out
    assert "hydraulic fault raised at" in out and "MON_Alarm frames read back" in out


def test_status_heartbeat_carries_the_counters(run) -> None:
    codec = FrameCodec.from_dbc()
    status_id = codec.message("MON_Status").frame_id
    values = [
        codec.decode_message(m).values for m in run["frames"] if m.arbitration_id == status_id
    ]
    assert values, "no MON_Status frame"
    rx = [v["RxFrames"] for v in values]
    assert rx == sorted(rx) and rx[-1] > 0  # no wrap in a 36k-frame run
    assert all(v["RejectedFrames"] == 0 and v["DroppedFrames"] == 0 for v in values)
