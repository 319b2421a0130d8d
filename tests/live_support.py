"""Helpers for the live-monitor tests: a daemon on a python-can virtual bus in-process, or
``monitor run`` as a process of its own (config file, log file, waiting on its output)."""

from __future__ import annotations

import dataclasses
import itertools
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import can
import numpy as np

from monitor.bus.replay import ReplayCounts, replay_log
from monitor.config.settings import BusConfig, MonitorConfig, load_config
from monitor.detection.offline import Detection
from monitor.detection.ticker import Ticker, event
from monitor.io.recording import Recording
from monitor.live.daemon import Daemon
from monitor.resources import resource_path
from monitor.sampling.sampler import ROW_COLUMNS

_channels = itertools.count()
REPO = Path(__file__).resolve().parents[1]


def write_config(tmp_path: Path, extra: str, base: bool = True, model: Path | None = None) -> Path:
    """``tmp_path/monitor.yaml``: the shipped DBC and ``model`` (default: the shipped
    model) on the reference machine (the shipped logs' and models trained on them) unless
    ``base`` is False, then ``extra`` YAML."""
    model = model or resource_path("config", "boom_default.model.npz")
    dbc = resource_path("dbc", "monitor.dbc")
    text = f"dbc: {dbc}\nmodel: {model}\nmachine_id: reference\n" if base else ""
    p = tmp_path / "monitor.yaml"
    p.write_text(text + extra)
    return p


def start_daemon(
    config: Path, cwd: Path, log_path: Path, env: dict[str, str] | None = None, nice: int = 0
) -> subprocess.Popen:
    """``monitor run --config CONFIG`` as a process of this tree, stderr to ``log_path``
    (``nice``: that much lower a priority than this process)."""
    full_env = {**os.environ, "PYTHONPATH": str(REPO), **(env or {})}
    with log_path.open("ab") as err:
        return subprocess.Popen(
            [sys.executable, "-m", "monitor", "run", "--config", str(config)],
            stdin=subprocess.DEVNULL,
            stderr=err,
            env=full_env,
            cwd=cwd,
            preexec_fn=(lambda: os.nice(nice)) if nice else None,
        )


def own_udp_port() -> int:
    """A free UDP port for a udp_multicast run of its own: on Linux a socket bound to a port
    hears every multicast group any process joined on it, so two runs on different groups
    but python-can's default port would hear each other."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("", 0))
        return int(s.getsockname()[1])


def wait_for_text(log_path: Path, text: str, proc: subprocess.Popen, timeout_s: float) -> None:
    """Wait until ``text`` is in the daemon's log; fail early (with the log) if it exits."""
    end = time.monotonic() + timeout_s
    while True:
        seen = log_path.read_text(errors="replace") if log_path.exists() else ""
        if text in seen:
            return
        if proc.poll() is not None or time.monotonic() > end:
            state = "timed out" if proc.poll() is None else f"exited {proc.returncode}"
            raise AssertionError(f"{text!r} not in the daemon's log ({state}):\n{seen[-3000:]}")
        time.sleep(0.1)


def live_config(tmp: Path, config: Path | None = None, **bus: Any) -> MonitorConfig:
    """The shipped config (or ``config``) on a fresh virtual channel, outputs under ``tmp``.

    Logs are replayed here as fast as the bus takes them, so the monitor's frames (timed on
    the sample clock) come many times faster than in the field: the wall-clock cap on them
    (``outputs.frames_max_per_s``, tested in test_own_frames) is lifted so that it drops
    none of the frames these tests compare."""
    cfg = load_config(config)
    opts = {
        "interface": "virtual",
        "channel": f"test-{next(_channels)}",
        "queue_frames": 200_000,
        "silent_s": 30.0,
        **bus,
    }
    return dataclasses.replace(
        cfg,
        bus=BusConfig(**opts),
        outputs=dataclasses.replace(cfg.outputs, frames_max_per_s=1e6),
        event_log=dataclasses.replace(cfg.event_log, path=tmp / "events.jsonl"),
        black_box=dataclasses.replace(cfg.black_box, directory=tmp / "blackbox"),
    )


def wait_until(cond: Callable[[], bool], timeout_s: float = 60.0) -> None:
    end = time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() > end:
            raise AssertionError("timed out waiting")
        time.sleep(0.01)


def settle(daemon: Daemon, sent: int, timeout_s: float = 60.0) -> None:
    """Wait until the daemon has taken ``sent`` frames off the bus and processed them."""
    wait_until(lambda: daemon.reader.counts.received + 0 >= sent, timeout_s)
    wait_until(lambda: daemon.codec.counts.frames >= sent - daemon.reader.counts.dropped, timeout_s)


def run_daemon(
    cfg: MonitorConfig, feed: Callable[[can.BusABC, Daemon], Any]
) -> tuple[Daemon, list[dict[str, Any]], list[can.Message], Any]:
    """A daemon on ``cfg``'s virtual channel with a sender and a listener beside it:
    ``feed(sender, daemon)`` puts frames on the bus and waits until they are taken; then
    the ordered stop.  Returns the daemon, its events, every frame the listener saw (ours
    and theirs) and what ``feed`` returned."""
    listener = can.Bus(interface="virtual", channel=cfg.bus.channel)
    sender = can.Bus(interface="virtual", channel=cfg.bus.channel, preserve_timestamps=True)
    events: list[dict[str, Any]] = []
    daemon = Daemon(cfg, on_event=events.append)
    daemon.start()
    try:
        fed = feed(sender, daemon)
    finally:
        daemon.stop()  # what SIGTERM does: ordered stop, event log fsynced
    sender.shutdown()
    return daemon, events, drain(listener), fed


def replay_settled(log: Path) -> Callable[[can.BusABC, Daemon], ReplayCounts]:
    """A ``run_daemon`` feed: ``log`` as fast as it goes (log time rules), then settle."""

    def feed(sender: can.BusABC, daemon: Daemon) -> ReplayCounts:
        counts = replay_log(log, sender, speed=None)
        settle(daemon, counts.sent)
        return counts

    return feed


def drain(bus: can.BusABC) -> list[can.Message]:
    """Every frame waiting on ``bus`` (then shut down)."""
    frames = []
    while (m := bus.recv(0)) is not None:
        frames.append(m)
    bus.shutdown()
    return frames


def send_all(bus: can.BusABC, msgs: Iterable[can.Message]) -> int:
    n = 0
    for m in msgs:
        m.channel = None
        bus.send(m)
        n += 1
    return n


def rows_of(rec: Recording) -> np.ndarray:
    cols = [rec[c] if rec.has(c) else np.full(len(rec), np.nan) for c in ROW_COLUMNS]
    return np.column_stack([rec.t, *cols])


def tick_recording(ticker: Ticker, rec: Recording) -> tuple[np.ndarray, list[dict[str, Any]]]:
    js, events = np.empty(len(rec)), []
    start = rec.meta.get("start_time_s")
    for i, row in enumerate(rows_of(rec)):
        tick = ticker.tick(row)
        js[i] = tick.j
        if tick.changed:
            events.append(event(tick, ticker.fault, ticker.eps0, start))  # type: ignore[arg-type]
    return js, events


def assert_same_events(live: list[dict[str, Any]], det: Detection | list[dict[str, Any]]) -> None:
    """Same state changes: t, state, fault and time exactly; J to rounding.

    J can differ in the last bits: the batch window runs in a numba kernel with
    reassociating fast-math, the per-tick one in plain float64.
    """
    offline = det.events if isinstance(det, Detection) else det
    assert [(e["t"], e["state"], e["fault"], e["time"]) for e in live] == [
        (e["t"], e["state"], e["fault"], e["time"]) for e in offline
    ]
    for a, b in zip(live, offline, strict=True):
        if b["J"] is None:
            assert a["J"] is None
        else:
            assert abs(a["J"] - b["J"]) <= 1e-9 * abs(b["J"])
        assert a["threshold"] == b["threshold"]


def events_of_frames(
    live: list[dict[str, Any]], t_end: float, ticked_to_s: float | None
) -> list[dict[str, Any]]:
    """The live events up to ``t_end``, the sample time of the last frame sent; after it at
    most the inactive of a silence the daemon heard before it was stopped.

    A daemon is stopped some wall time after the last frame.  Had its reader heard
    ``bus.silent_s`` of silence by then (under load the detector is seconds behind the
    reader, so when it catches up that silence is already proven), the daemon rightly ran
    the sample clock on past the last frame (to ``ticked_to_s``, its ``last_t_s``) and went
    inactive: the one change that silence may add, and only if the clock ran on.  Whether
    it did depends on wall time, not on the frames, so a test of the frames cannot ask."""
    sent = [e for e in live if e["t"] <= t_end + 1e-6]
    after = [e for e in live if e["t"] > t_end + 1e-6]
    assert ticked_to_s is not None
    if ticked_to_s <= t_end + 1e-6 or (sent and sent[-1]["state"] == "inactive"):
        assert after == []  # no silence proven after the last frame, or inactive already
    else:
        assert [e["state"] for e in after] == ["inactive"]
        assert t_end < after[0]["t"] <= ticked_to_s
    return sent


def assert_same_events_as_sent(
    live: list[dict[str, Any]], det: Detection, ticked_to_s: float | None
) -> list[dict[str, Any]]:
    """``assert_same_events`` for the frames sent: the desk's log ends at its last frame,
    the daemon may have heard silence after it (``events_of_frames``).  Returns the live
    events up to that frame."""
    sent = events_of_frames(live, float(det.t[-1]), ticked_to_s)
    assert_same_events(sent, det)
    return sent


def sigint_default() -> None:
    """``preexec_fn`` of a helper process that the tests stop with SIGINT (python-can's
    logger, candump): its SIGINT back to the default.  A suite run in the background of a
    shell without job control inherits SIGINT ignored, and the helper would ignore the
    stop and hang."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
