"""Silence is proven by the data or by the reader, never by a starved thread: the frame
pipeline (thread-free) driven by hand, with the reader's view given as numbers."""

from __future__ import annotations

import pytest

from monitor.bus.reader import BusConfig
from monitor.codec.frames import FrameCodec
from monitor.config.settings import load_config
from monitor.errors import ConfigError
from monitor.io.candump import read_candump
from monitor.live.loops import Loop, row_layout
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
    return FramePipeline(codec, columns, loops, lambda msg: None,
                         lambda tick, lp: changes.append(tick.state.label), 0.5, 1.0,
                         lambda: reader.heard_until, lambda: reader.backlog)  # fmt: skip


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
    reader.heard_until = p._last_ok_mono - 1.0
    p.silence()
    assert p.last_t_s == last
    # The reader proved 2 s of silence, but frames wait in the queue: still not silence.
    reader.heard_until, reader.backlog = p._last_ok_mono + 2.0, True
    p.silence()
    assert p.last_t_s == last and "inactive" not in changes


def test_silence_the_reader_proves_runs_the_clock_on_and_the_monitor_goes_inactive() -> None:
    reader, changes = Reader(), []
    p = pipeline(reader, changes)
    fed(p, 5.0)
    last = p.last_t_s
    reader.heard_until = p._last_ok_mono + 2.0  # an empty receive began 2 s after it
    p.silence()
    assert p.last_t_s == pytest.approx(last + 2.0, abs=0.011)
    assert changes[-1] == "inactive"  # the rows went stale: engine speed unknown


def test_a_frame_of_any_kind_proves_time_passed() -> None:
    import can

    reader, changes = Reader(), []
    p = pipeline(reader, changes)
    fed(p, 5.0)
    last = p.last_t_s
    t_bus = p.bus_time(last) + 3.0  # a foreign frame 3 s after the last sensor frame
    p.feed(can.Message(arbitration_id=0x123, data=b"\x00", is_extended_id=False,
                       timestamp=t_bus))  # fmt: skip
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
