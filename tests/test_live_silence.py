"""Silence is proven by the data or by the reader, never by a starved thread: the frame
pipeline (thread-free) driven by hand, with the reader's view given as numbers."""

from __future__ import annotations

import itertools
from pathlib import Path

import can
import pytest
from live_support import live_config, wait_until

from monitor.bus.reader import BusConfig, BusReader
from monitor.codec.frames import FrameCodec
from monitor.config.layout import row_layout
from monitor.config.settings import load_config
from monitor.errors import ConfigError
from monitor.io.candump import read_candump
from monitor.live.daemon import Daemon
from monitor.live.loops import Loop
from monitor.live.pipeline import FramePipeline
from monitor.resources import resource_path


class Reader:
    """What the reader thread knows: when its last empty receive began, whether frames wait."""

    heard_until = -float("inf")
    backlog = False


def pipeline(reader: Reader, changes: list) -> FramePipeline:
    cfg = load_config()
    codec = FrameCodec.from_dbc(cfg.dbc)
    columns, views = row_layout(cfg, codec)
    loops = [Loop(lc, cfg, codec, v) for lc, v in zip(cfg.monitored_loops, views, strict=True)]
    return FramePipeline(
        codec,
        columns,
        loops,
        lambda msg: None,
        lambda tick, lp: changes.append(tick.state.label),
        0.5,
        1.0,
        lambda: reader.heard_until,
        lambda: reader.backlog,
    )


def fed(p: FramePipeline, seconds: float) -> None:
    """The first ``seconds`` of the shipped normal log, one frame at a time."""
    t0 = None
    for msg in read_candump(resource_path("replay", "normal.log")):
        t0 = msg.timestamp if t0 is None else t0
        if msg.timestamp - t0 > seconds:
            return
        p.feed(msg)


def test_a_starved_reader_or_a_backlog_is_not_silence() -> None:
    reader, changes = Reader(), []
    p = pipeline(reader, changes)
    fed(p, 5.0)
    last = p.last_t_s
    # Wall time runs on (the detector thread woke up late) but the reader has not proven
    # any silence: its last empty receive began before the last frame was taken.
    reader.heard_until = p.proof._last_ok_mono - 1.0
    p.silence()
    assert p.last_t_s == last
    # The reader proved 2 s of silence, but frames wait in the queue: still not silence.
    reader.heard_until, reader.backlog = p.proof._last_ok_mono + 2.0, True
    p.silence()
    assert p.last_t_s == last and "inactive" not in changes


def test_silence_the_reader_proves_runs_the_clock_on_and_the_monitor_goes_inactive() -> None:
    reader, changes = Reader(), []
    p = pipeline(reader, changes)
    fed(p, 5.0)
    last = p.last_t_s
    reader.heard_until = p.proof._last_ok_mono + 2.0  # an empty receive began 2 s after it
    p.silence()
    assert p.last_t_s == pytest.approx(last + 2.0, abs=0.011)
    assert changes[-1] == "inactive"  # the rows went stale: engine speed unknown


def test_a_frame_of_any_kind_proves_time_passed() -> None:
    reader, changes = Reader(), []
    p = pipeline(reader, changes)
    fed(p, 5.0)
    last = p.last_t_s
    t_bus = p.bus_time(last) + 3.0  # a foreign frame 3 s after the last sensor frame
    p.feed(can.Message(arbitration_id=0x123, data=b"\x00", is_extended_id=False, timestamp=t_bus))
    assert p.last_t_s == pytest.approx(last + 3.0, abs=0.011)
    assert changes[-1] == "inactive"


@pytest.mark.parametrize("scale", [0.25, 0.0, float("nan"), 1000.0])
def test_a_time_scale_the_sampler_cannot_honour_is_refused(scale: float, tmp_path) -> None:
    with pytest.raises(ConfigError, match="bus.time_scale must be within 0.5..100"):
        BusConfig(time_scale=scale)
    yaml = tmp_path / "m.yaml"
    yaml.write_text(f"bus: {{time_scale: {scale}}}\n")
    with pytest.raises(ConfigError, match=rf"{yaml}: bus.time_scale"):
        load_config(yaml)


# The reader's own receive stamps (BusReader.received_at) as the daemon wires them.
def _pipeline(tmp_path: Path, reader: dict) -> tuple[FramePipeline, Daemon]:
    cfg = live_config(tmp_path, silent_s=0.5)
    daemon = Daemon(cfg)  # not started: its codec and loops only
    pipe = FramePipeline(
        daemon.codec,
        daemon.columns,
        daemon.loops,
        lambda m: None,
        lambda t, lp: None,
        cfg.bus.silent_s,
        1.0,
        heard_until=lambda: reader["heard"],
        backlog=lambda: reader["backlog"],
        received_at=lambda: reader["rx"],
    )
    return pipe, daemon


def _frames(seconds: float) -> list[can.Message]:
    out = []
    with can.CanutilsLogReader(resource_path("replay", "normal.log")) as frames:
        for m in frames:
            if out and m.timestamp - out[0].timestamp > seconds:
                break
            out.append(m)
    return out


def test_only_the_readers_own_view_runs_the_clock_on(tmp_path: Path) -> None:
    reader = {"heard": float("-inf"), "rx": 1000.0, "backlog": False}
    pipe, daemon = _pipeline(tmp_path, reader)
    try:
        for m in _frames(5.0):
            pipe.feed(m)
        t_last = pipe.last_t_s
        assert t_last is not None
        # Frames wait in the queue (a starved detector): never silence, however old.
        reader.update(heard=1010.0, backlog=True)
        pipe.silence()
        assert pipe.last_t_s == t_last
        # The reader heard nothing for less than bus.silent_s since its latest frame.
        reader.update(heard=1000.4, backlog=False)
        pipe.silence()
        assert pipe.last_t_s == t_last
        # A frame received after the empty receive began proves nothing either.
        reader.update(heard=1001.0, rx=1001.2)
        pipe.silence()
        assert pipe.last_t_s == t_last
        # The reader's empty receive began 1.0 s after its latest frame: 1.0 s of silence.
        reader.update(heard=1002.2)
        pipe.silence()
        assert pipe.last_t_s == pytest.approx(t_last + 1.0, abs=0.011)
    finally:
        daemon.reader.bus.shutdown()


def test_frames_stamped_ahead_of_the_readers_clock_do_not_run_the_clock_on(tmp_path) -> None:
    """A flood of foreign frames stamped 300 s ahead, received within 0.2 s, then 3 s later
    by the reader's clock: the sample clock runs on by what the reader saw, not 300 s."""
    reader = {"heard": float("-inf"), "rx": 1000.0, "backlog": False}
    pipe, daemon = _pipeline(tmp_path, reader)
    try:
        frames = _frames(5.0)
        for m in frames:
            pipe.feed(m)
        t_last = pipe.last_t_s
        assert t_last is not None
        ahead = frames[-1].timestamp + 300.0
        for k in range(200):
            reader["rx"] = 1000.0 + k * 0.001
            pipe.feed(
                can.Message(
                    arbitration_id=0x123, data=bytes(8), is_extended_id=False, timestamp=ahead + k
                )
            )
        assert pipe.last_t_s == t_last  # 0.2 s by the reader's clock: under bus.silent_s
        reader["rx"] = 1003.0
        pipe.feed(
            can.Message(
                arbitration_id=0x123, data=bytes(8), is_extended_id=False, timestamp=ahead + 500
            )
        )
        assert pipe.last_t_s == pytest.approx(t_last + 3.0, abs=0.011)
    finally:
        daemon.reader.bus.shutdown()


def test_the_reader_stamps_each_frame_when_it_receives_it() -> None:
    ticks = itertools.count(1)
    bus = can.Bus(interface="virtual", channel="silence-stamp")
    sender = can.Bus(interface="virtual", channel="silence-stamp")
    reader = BusReader(bus, 10, poll_s=0.01, clock=lambda: float(next(ticks)))
    assert reader.received_at == float("-inf")
    reader.start()
    try:
        sender.send(can.Message(arbitration_id=0x123, data=b"\x01"))
        wait_until(lambda: not reader.queue.empty())
        stamp = reader.received_at
        assert stamp >= 1.0 and stamp == int(stamp)  # one of the reader's clock readings
        # Every later empty receive begins after it: silence is measured from the stamp.
        wait_until(lambda: reader.heard_until > stamp)
    finally:
        reader.stop()
        bus.shutdown()
        sender.shutdown()


def test_the_bus_socket_gets_a_receive_buffer_of_seconds_not_milliseconds() -> None:
    """A starved reader leaves frames in the kernel's buffer; the default (~200 kB) drops
    them within a fraction of a second of a busy bus, so the monitor asks for 4 MiB (up to
    net.core.rmem_max unless privileged; Linux reports twice what it grants)."""
    pytest.importorskip("msgpack")
    from live_support import own_udp_port

    from monitor.bus.reader import RCVBUF_BYTES, BusConfig, open_bus

    rmem_max = int(Path("/proc/sys/net/core/rmem_max").read_text())
    bus = open_bus(
        BusConfig(
            interface="udp_multicast", channel="239.74.163.12", options={"port": own_udp_port()}
        )
    )
    try:
        import socket

        got = bus._multicast._socket.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
    finally:
        bus.shutdown()
    assert got >= 2 * min(RCVBUF_BYTES, rmem_max)
