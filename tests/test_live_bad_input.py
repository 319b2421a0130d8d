"""Bad input on the bus is counted and survived, and never raises a hydraulic fault:
wrong DLC, bad checksum, counter jumps, a 10x flood, a sensor that stops, time that jumps
backwards, the engine stopping, the whole bus going silent."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import can
import pytest
from live_support import events_of_frames, live_config, send_all, settle, wait_until

from monitor.codec.frames import FrameCodec
from monitor.detection.alarm import State
from monitor.io.candump import read_candump
from monitor.live.daemon import Daemon
from monitor.model.modelfile import load_model
from monitor.resources import resource_path

WINDOW_S = load_model(resource_path("config", "boom_default.model.npz")).window_n / 100.0
SECONDS = WINDOW_S + 12.0  # the J window is full after WINDOW_S, so J is live for 12 s
Edit = Callable[[float, str, dict[str, float]], list[tuple[float, dict[str, float]]]]


def frames(edit: Edit | None = None, seconds: float = SECONDS) -> list[can.Message]:
    """The first ``seconds`` of the normal log, re-encoded (valid counters and CRCs) after
    ``edit(t_rel, message, values)`` -> [(t_rel, values), ...] (empty: frame dropped)."""
    rx, tx = FrameCodec.from_dbc(), FrameCodec.from_dbc()
    out: list[can.Message] = []
    t0 = None
    for m in read_candump(resource_path("replay", "normal.log")):
        t0 = m.timestamp if t0 is None else t0
        t = m.timestamp - t0
        if t > seconds:
            break
        d = rx.decode_message(m)
        items = [(t, d.values)] if edit is None else edit(t, d.name, dict(d.values))
        for tt, values in items:
            out.append(tx.encode_message(d.name, values, t0 + tt))
    return out


def run_daemon(tmp_path, msgs: list[can.Message], **bus: Any) -> tuple[Daemon, list[dict]]:
    cfg = live_config(tmp_path, **bus)
    events: list[dict] = []
    daemon = Daemon(cfg, on_event=events.append)
    sender = can.Bus(interface="virtual", channel=cfg.bus.channel, preserve_timestamps=True)
    daemon.start()
    try:
        settle(daemon, send_all(sender, msgs))
    finally:
        daemon.stop()
        sender.shutdown()
    assert daemon.error is None
    return daemon, events


def states(events: list[dict]) -> list[str]:
    return [e["state"] for e in events]


def test_clean_stream_stays_normal(tmp_path) -> None:
    daemon, events = run_daemon(tmp_path, frames())
    assert states(events) == ["normal"]
    assert daemon.counts()["counter_jumps"] == 0


def test_wrong_dlc_and_bad_crc_are_counted(tmp_path) -> None:
    msgs = frames()
    flow = [i for i, m in enumerate(msgs) if m.arbitration_id == 0x8CFF1121 & 0x1FFFFFFF]
    for i in flow[1000:1005]:
        msgs[i].data = msgs[i].data[:7]
        msgs[i].dlc = 7
    for i in flow[1500:1506]:
        msgs[i].data[7] ^= 0x5A
    daemon, events = run_daemon(tmp_path, msgs)
    c = daemon.counts()
    assert c["rejected"]["dlc"] == 5 and c["rejected"]["crc"] == 6
    assert "fault" not in states(events)


def test_counter_jumps_are_counted(tmp_path) -> None:
    msgs = frames()
    press = [i for i, m in enumerate(msgs) if m.arbitration_id == 0x0CFF1021]
    for i in sorted((press[300], press[900], press[1500]), reverse=True):
        del msgs[i]  # a lost frame: the next counter jumps by 2
    daemon, events = run_daemon(tmp_path, msgs)
    assert daemon.counts()["counter_jumps"] == 3
    assert "fault" not in states(events)


def test_flood_at_ten_times_the_rate_is_survived(tmp_path) -> None:
    def flood(t: float, name: str, values: dict) -> list:
        if name == "HYD_Pressures" and 12.0 <= t < 16.0:
            return [(t + k * 0.001, values) for k in range(10)]  # 1 kHz instead of 100 Hz
        return [(t, values)]

    msgs = frames(flood)
    daemon, events = run_daemon(tmp_path, msgs)
    c = daemon.counts()
    assert c["received"] == len(msgs) and c["dropped"] == 0
    assert c["per_message"]["HYD_Pressures"] > 10 * 400  # the flood was decoded, not lost
    assert states(events) == ["normal"]


def test_flood_beyond_the_queue_is_counted_as_dropped(tmp_path) -> None:
    def flood(t: float, name: str, values: dict) -> list:
        if name == "HYD_Pressures" and 12.0 <= t < 16.0:
            return [(t + k * 0.001, values) for k in range(10)]
        return [(t, values)]

    msgs = frames(flood)
    cfg_queue = 100  # far too small for a burst sent as fast as the bus takes it
    daemon, events = run_daemon(tmp_path, msgs, queue_frames=cfg_queue)
    c = daemon.counts()
    assert c["dropped"] > 0
    assert c["received"] == len(msgs) == c["frames"] + c["dropped"]  # nothing silent
    assert "fault" not in states(events)


def test_a_sensor_that_stops_is_a_sensor_fault_that_recovers(tmp_path) -> None:
    def stop_flow(t: float, name: str, values: dict) -> list:
        return [] if name == "HYD_Flow" and 14.0 <= t < 16.0 else [(t, values)]

    daemon, events = run_daemon(tmp_path, frames(stop_flow))
    assert states(events) == ["normal", "sensor_fault", "normal"]
    assert 14.0 < events[1]["t"] < 14.1 and 16.0 < events[2]["t"] < 16.3


def test_time_jumping_backwards_is_followed(tmp_path) -> None:
    def jump(t: float, name: str, values: dict) -> list:
        return [(t - 100.0 if t >= 12.0 else t, values)]  # the logger's clock was reset

    daemon, events = run_daemon(tmp_path, frames(jump))
    c = daemon.counts()
    assert c["time_resyncs"] == 1
    assert "fault" not in states(events)
    assert c["ticks"] == pytest.approx(SECONDS * 100, abs=5)  # one clock, no hole


def test_engine_stopped_is_inactive_and_resumes(tmp_path) -> None:
    stop_s = WINDOW_S + 3.0  # J is defined before the engine stops

    def engine_off(t: float, name: str, values: dict) -> list:
        if name == "HYD_Commands" and stop_s <= t < stop_s + 3.0:
            values["EngineSpeed"] = 0.0
        return [(t, values)]

    daemon, events = run_daemon(tmp_path, frames(engine_off, seconds=stop_s + 9.0))
    assert states(events) == ["normal", "inactive", "normal"]
    # The window was held, not restarted: J is defined 6 s after the restart, far less than
    # the window a fresh start needs.
    assert daemon.loops[0].last_j == daemon.loops[0].last_j


def test_whole_bus_silent_is_inactive_and_resumes(tmp_path) -> None:
    stop_s = WINDOW_S + 5.0  # J is defined before the bus goes silent
    msgs = frames(seconds=stop_s + 5.0)
    t0 = msgs[0].timestamp
    first = [m for m in msgs if m.timestamp - t0 < stop_s]
    rest = [m for m in msgs if m.timestamp - t0 >= stop_s]
    for m in rest:
        m.timestamp += 5.0  # the machine was off 5 s
    cfg = live_config(tmp_path, silent_s=0.2)
    events: list[dict] = []
    daemon = Daemon(cfg, on_event=events.append)
    sender = can.Bus(interface="virtual", channel=cfg.bus.channel, preserve_timestamps=True)
    daemon.start()
    try:
        settle(daemon, send_all(sender, first))
        wait_until(lambda: daemon.state is State.INACTIVE, 20.0)
        settle(daemon, len(first) + send_all(sender, rest))
    finally:
        daemon.stop()
        sender.shutdown()
    # The daemon may also have heard the bus silent after the last frame (wall time).
    t_end = rest[-1].timestamp - t0
    events = events_of_frames(events, t_end, daemon.pipeline.last_t_s)
    assert states(events) == ["normal", "inactive", "normal"]
    assert stop_s < events[1]["t"] < stop_s + 0.1
    # Window held: J defined 5 s after the restart.  Unless that trailing silence ran the
    # sample clock on past the last frame: its inactive ticks carry no J (events_of_frames).
    ran_on = daemon.pipeline.last_t_s > t_end + 1e-6
    assert daemon.loops[0].last_j == daemon.loops[0].last_j or ran_on


def test_frames_with_unbelievable_timestamps_are_ignored_and_counted(tmp_path) -> None:
    """Frames stamped 1e20 s, infinity, NaN or before 1970 among good ones: ignored and
    counted, the events exactly those of the log without them."""
    good = frames()
    stamps = [1e20, float("inf"), float("nan"), -5.0]
    bad = [
        can.Message(timestamp=ts, arbitration_id=m.arbitration_id, is_extended_id=True, data=m.data)
        for ts, m in zip(stamps, good[1500:1504], strict=True)
    ]
    _, clean = run_daemon(tmp_path / "a", good)
    events: list[dict] = []
    daemon = Daemon(live_config(tmp_path / "b"), on_event=events.append)
    with can.Bus(
        interface="virtual", channel=daemon.cfg.bus.channel, preserve_timestamps=True
    ) as sender:
        daemon.start()
        try:
            n = send_all(sender, good[:1500] + bad + good[1500:])
            wait_until(lambda: daemon.reader.counts.received >= n)
            settle(daemon, len(good))
        finally:
            daemon.stop()
    assert daemon.error is None and daemon.counts()["bad_timestamps"] == 4
    assert [(e["t"], e["state"]) for e in events] == [(e["t"], e["state"]) for e in clean]
