"""DM1/DM2 from the daemon on a python-can virtual bus: shipped logs replayed onto the bus,
every J1939 frame read back and checked by an independent J1939 receiver (can-j1939).
Times are sample-clock (log) times, never wall time."""

from __future__ import annotations

from typing import Any

import can
import numpy as np
import pytest
from j1939_support import DM1_ID, TP_CM_ID, TP_DT_ID, decode_dm, dm_dbc, reassemble
from live_support import live_config, run_daemon, send_all, wait_until

from monitor.bus.replay import replay_log
from monitor.codec.frames import FrameCodec
from monitor.codec.j1939.dtc import PGN_DM1, PGN_DM2
from monitor.codec.j1939.transport import frame_id
from monitor.io.candump import read_candump
from monitor.live.daemon import Daemon
from monitor.live.outputs import ALARM
from monitor.resources import resource_path

J1939_IDS = {DM1_ID, TP_CM_ID, TP_DT_ID, 0x18FECBA0}
PRESSURES = 0x0CFF1021  # HYD_Pressures: PP, PA, PB


def _run(tmp, feed) -> dict[str, Any]:
    cfg = live_config(tmp)

    def fed(sender: can.BusABC, daemon: Daemon) -> float:
        t0, sent, requests = feed(sender)
        wait_until(lambda: daemon.reader.counts.received >= sent)
        # Requests for us are answered, not decoded: the codec sees the other frames.
        wait_until(lambda: daemon.codec.counts.frames >= sent - requests)
        return t0

    daemon, events, frames, t0 = run_daemon(cfg, fed)
    j1939_frames = [m for m in frames if m.arbitration_id in J1939_IDS]
    return {
        "cfg": cfg,
        "daemon": daemon,
        "t0": t0,
        "frames": frames,
        "events": events,
        "groups": reassemble(j1939_frames),
        "j1939": j1939_frames,
    }


def _dm1s(run: dict[str, Any]) -> list[tuple[float, Any, Any]]:
    """(log time, lamps, DTCs) of every DM1 (single frame or BAM) read back."""
    return [
        (g["t"] - run["t0"], *decode_dm(g["data"])) for g in run["groups"] if g["pgn"] == PGN_DM1
    ]


@pytest.fixture(scope="module")
def hydraulic(tmp_path_factory) -> dict[str, Any]:
    def feed(sender):
        counts = replay_log(resource_path("replay", "spool_wear.log"), sender, speed=None)
        return counts.first_ts, counts.sent, 0

    return _run(tmp_path_factory.mktemp("dm1"), feed)


def test_dm1_announces_the_hydraulic_fault_with_the_alarm_and_every_second(hydraulic) -> None:
    codec = FrameCodec.from_dbc()
    alarm_id = codec.message(ALARM).frame_id
    alarms = [
        (m.timestamp - hydraulic["t0"], codec.decode_message(m).values)
        for m in hydraulic["frames"]
        if m.arbitration_id == alarm_id
    ]
    t_alarm = next(t for t, v in alarms if v["State"] == 1)
    dm1 = _dm1s(hydraulic)
    assert dm1[0][2] == [(0, 0, 0)] and dm1[0][0] == pytest.approx(alarms[0][0])
    before = [t for t, _, d in dm1 if t < t_alarm - 1e-6]
    assert all(d == [(0, 0, 0)] for t, _, d in dm1 if t < t_alarm - 1e-6)
    assert np.diff(before) == pytest.approx(1.0, abs=1e-6)
    fault = [(t, lamps, d) for t, lamps, d in dm1 if t >= t_alarm - 1e-6]
    assert fault[0][0] == pytest.approx(t_alarm, abs=1e-6)  # the same tick as MON_Alarm
    assert all(d == [(520194, 7, 1)] for _, _, d in fault)  # spool_wear, first occurrence
    assert fault[0][1] == {"protect": "off", "amber": "on", "red": "off", "mil": "off"}
    times = [t for t, _, _ in fault]
    assert len(times) >= 10
    assert np.diff(times) == pytest.approx(1.0, abs=0.011)
    # Single frames only (one DTC), which the shipped DM1 DBC decodes as well.
    assert {m.arbitration_id for m in hydraulic["j1939"]} == {DM1_ID}
    last = dm_dbc().decode_message(DM1_ID, hydraulic["j1939"][-1].data, decode_choices=False)
    assert last["SPN_High3"] * 65536 + last["SPN_Low16"] == 520194 and last["FMI"] == 7
    c = hydraulic["daemon"].counts()
    assert c["dm1_messages"] == len(dm1) == c["j1939_frames"] and c["j1939_held_back"] == 0


@pytest.fixture(scope="module")
def sensor(tmp_path_factory) -> dict[str, Any]:
    """30 s of the normal log, the pressure frames missing from 10 to 12 s; a DM2 request
    to the monitor at 20 s and one to another ECU at 21 s."""

    def feed(sender):
        msgs = list(read_candump(resource_path("replay", "normal.log")))
        t0 = msgs[0].timestamp
        keep = [
            m
            for m in msgs
            if m.timestamp - t0 < 30.0
            and not (m.arbitration_id == PRESSURES and 10.0 <= m.timestamp - t0 < 12.0)
        ]
        for at, to in ((20.0, 0xA0), (21.0, 0x17)):
            req = can.Message(
                timestamp=t0 + at,
                arbitration_id=frame_id(59904, 0xF9, 6, to),
                data=PGN_DM2.to_bytes(3, "little"),
            )
            keep.insert(next(i for i, m in enumerate(keep) if m.timestamp > req.timestamp), req)
        return t0, send_all(sender, keep), 1

    return _run(tmp_path_factory.mktemp("dm1s"), feed)


def test_sensor_fault_dm1_is_a_bam_and_clears_to_no_dtc(sensor) -> None:
    states = [(e["t"], e["state"]) for e in sensor["events"]]
    t_on = next(t for t, s in states if s == "sensor_fault")
    t_off = next(t for t, s in states if t > t_on and s != "sensor_fault")
    assert 10.0 < t_on < 10.2 and 12.0 < t_off < 12.3
    cms = [m for m in sensor["j1939"] if m.arbitration_id == TP_CM_ID]
    dm1_cms = [m.timestamp - sensor["t0"] for m in cms if m.data[5:8] == b"\xca\xfe\x00"]
    assert bytes(cms[0].data) == bytes((32, 14, 0, 2, 0xFF, 0xCA, 0xFE, 0x00))
    # A BAM at the change and every second while the fault lasts (2.06 s: three).
    assert dm1_cms == pytest.approx([t_on, t_on + 1.0, t_on + 2.0], abs=1e-6)
    dts = [m.timestamp - sensor["t0"] for m in sensor["j1939"] if m.arbitration_id == TP_DT_ID]
    for cm_t in dm1_cms:  # data packets 50 ms apart (J1939-21: 50-200 ms)
        mine = [t for t in dts if cm_t < t < cm_t + 0.2]
        assert [t - cm_t for t in mine] == pytest.approx([0.05, 0.10], abs=1e-6)
    pressures = [(520212, 9, 1), (520213, 9, 1), (520214, 9, 1)]
    dm1 = _dm1s(sensor)  # timed at their last frame
    bams = [(t, d) for t, _, d in dm1 if len(d) > 1]
    assert [d for _, d in bams] == [pressures] * 3
    after = [(t, d) for t, _, d in dm1 if t > bams[-1][0]]
    assert all(d == [(0, 0, 0)] for _, d in after)
    # Cleared at t_off, announced once the BAM under way (started at t_on + 2) has ended.
    assert t_on + 2.1 < after[0][0] <= t_on + 2.1 + 0.011 and after[0][0] > t_off
    assert np.diff([t for t, _ in after]) == pytest.approx(1.0, abs=1e-6)


def test_dm2_answers_the_request_with_the_previously_active_dtcs(sensor) -> None:
    dm2 = [g for g in sensor["groups"] if g["pgn"] == PGN_DM2]
    assert len(dm2) == 1  # the request to 0x17 is not for us
    (cm,) = [m for m in sensor["j1939"] if m.arbitration_id == TP_CM_ID and m.data[5] == 0xCB]
    assert 20.0 <= cm.timestamp - sensor["t0"] <= 20.011  # the tick after the request
    lamps, dtcs = decode_dm(dm2[0]["data"])
    assert dtcs == [(520212, 9, 1), (520213, 9, 1), (520214, 9, 1)]
    assert lamps["amber"] == "off"  # nothing is active now
    assert sensor["daemon"].counts()["j1939_requests"] == 1


def test_a_reopened_bus_still_passes_j1939_requests(tmp_path) -> None:
    """After a bus failure the reader opens a new bus: its kernel filters must still let
    requests for our DM1/DM2 through, or service tools get no answer after an outage."""
    daemon = Daemon(live_config(tmp_path))
    try:
        bus = daemon.reader.opener()
        request = can.Message(arbitration_id=0x18EAA0F9, data=b"\xcb\xfe\x00")  # DM2 to 0xA0
        other = can.Message(arbitration_id=0x18FEF100, data=bytes(8))  # CCVS: not ours
        assert bus._matches_filters(request) and not bus._matches_filters(other)
        bus.shutdown()
    finally:
        daemon.stop()
