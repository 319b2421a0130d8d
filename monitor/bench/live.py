"""Benchmark 2 and 4: the live daemon on a python-can virtual bus, timed from the inside.

Run as its own process (``python -m monitor.bench.live ...``, which ``monitor bench``
does), so that its peak memory is the daemon's and no benchmark thread shares its GIL
except the sender, which puts a simulated run on the bus with the log's timing at
``--speed`` times real time (frames carry their log timestamps, so the sample clock is the
machine's).

Timing points, all ``time.perf_counter`` in this process:

* arrival: the daemon's bus reader takes the frame off the bus (a wrapper around
  ``recv``; the detector thread takes frames in the same order);
* tick: the ticker returned its result for a row.  A row is complete when the first frame
  of the next 10 ms instant arrives (the sampler cannot know earlier that no more frames of
  its instant will come), so a tick's latency is measured from that frame's arrival;
* alarm frame: the daemon's send of MON_Alarm for a tick whose state changed.

The wrappers sit where the detector thread calls (the frame pipeline's ``feed``, ``send`` and
``on_change``, each loop's ticker), so they see every frame, alarm and state change.

CPU per tick is the detector thread's ``time.thread_time`` across ``Ticker.tick``.

``--loops 4`` runs the daemon with four loops (config/excavator4.yaml, every loop on the
benchmark's model and the same simulated run, so every row costs four full ticks): then a
tick's latency runs to the last loop's result for the row, and its CPU is the four ticks'
sum: the per-row budget of a four-loop machine.  The config's pump rule (``pump:``) ticks after
the loops in each row: its tick (``MachineWatch.tick``: the rule, MON_Alarm_Pump and its
DM1) is timed apart (``pump_tick_cpu_*_us``) and with the row (``row_with_pump_*``).

``--writes inline`` runs the event log's fsync and the black-box dumps in the detector thread
(the path before the disk-writer thread, ``monitor.live.writer``); ``--writes thread,inline
--rounds R`` alternates the two, R daemons each, in this one process and reports both and
their ratios (the top-level keys are the first mode's; peak memory is taken after the first
daemon, so it is one daemon's).
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import json
import resource
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import can
import numpy as np

from monitor.bench.data import test_recording
from monitor.bench.pump_tick import PumpProbe
from monitor.codec.frames import FrameCodec
from monitor.config.settings import BusConfig, MonitorConfig, load_config
from monitor.detection.ticker import Tick
from monitor.io.recording import Recording
from monitor.live.daemon import Daemon
from monitor.live.loops import Loop
from monitor.offline.recordings import wide_recording
from monitor.resources import resource_path

START_TIME_S = 1_700_000_000.0


class _TimedBus:
    """The daemon's bus, noting when each frame is taken off it."""

    def __init__(self, bus: can.BusABC, arrivals: collections.deque) -> None:
        self._bus = bus
        self._arrivals = arrivals

    def recv(self, timeout: float | None = None) -> can.Message | None:
        msg = self._bus.recv(timeout)
        if msg is not None:
            self._arrivals.append(time.perf_counter())
        return msg

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self._bus.send(msg, timeout)

    def shutdown(self) -> None:
        self._bus.shutdown()


def _wrap(obj: object, name: str, timed: Callable[..., Any]) -> None:
    """Replace method ``name`` of the instance ``obj`` by its timed wrapper (an assignment
    mypy cannot type: a bound method replaced on one instance)."""
    setattr(obj, name, timed)


def _frames(codec: FrameCodec, rec: Recording) -> list[tuple[float, str, dict[str, float]]]:
    """(time s, message, values) in send order: per 10 ms sample, every DBC message whose
    signals ``rec`` has, at its cycle time (the oil temperature at 1 Hz), in DBC order."""
    msgs = [
        (info.name, info.signal_names, max(1, round(info.cycle_time_s / 0.01)))
        for info in codec.messages.values()
        if info.cycle_time_s and info.signal_names and all(rec.has(n) for n in info.signal_names)
    ]
    cols = {n: rec[n].tolist() for _, names, _ in msgs for n in names}
    plan = []
    for i, ti in enumerate(rec.t.tolist()):
        for name, names, every in msgs:
            if i % every == 0:
                plan.append((ti, name, {s: cols[s][i] for s in names}))
    return plan


def _config(model: Path, horizon: int, loops: int, channel: str, tmp: Path) -> MonitorConfig:
    base = load_config(resource_path("config", "excavator4.yaml") if loops == 4 else None)
    base = dataclasses.replace(
        base, loops=tuple(dataclasses.replace(lc, model=model) for lc in base.loops)
    )
    return dataclasses.replace(
        base,
        model=model,
        horizon=horizon,
        bus=BusConfig(interface="virtual", channel=channel, queue_frames=200_000),
        event_log=dataclasses.replace(base.event_log, path=tmp / "events.jsonl"),
        black_box=dataclasses.replace(base.black_box, directory=tmp / "blackbox"),
    )


class _Probe:
    """The timed wrappers around what the daemon's detector thread calls (each loop's
    ``Ticker.tick``, and the frame pipeline's input ``feed`` and outputs ``send`` and
    ``on_change``), and what they note."""

    def __init__(self, daemon: Daemon, arrivals: collections.deque[float]) -> None:
        self.arrivals = arrivals
        self.alarm_ids = {
            daemon.codec.message(lp.cfg.alarm_message).frame_id for lp in daemon.loops
        }
        self.last = len(daemon.loops) - 1
        self.latency: list[float] = []  # per row: arrival of the frame completing it -> ticked
        self.cpu: list[float] = []  # per row: the loops' tick CPU
        self.row_t: list[float] = []  # per row: its time
        self.change_t: list[float] = []  # rows where any loop's tick changed
        self.alarm_latency: list[float] = []  # MON_Alarm of a state change: arrival -> send
        self.change_wall: list[float] = []  # what a state change cost the detector thread
        self.change_cpu: list[float] = []
        # state_changed: this loop's tick changed state (its MON_Alarm follows);
        # row_changed: any loop's tick changed (state or gating: an event) in this row.
        self.current: dict[str, Any] = {
            "arrival": 0.0,
            "state_changed": False,
            "row_changed": False,
            "stopping": False,
            "cpu": 0.0,
        }
        pipeline = daemon.pipeline
        for k, lp in enumerate(daemon.loops):
            _wrap(lp.ticker, "tick", self._timed_tick(k, lp.ticker.tick))
        # The pump rule (config/excavator4.yaml's `pump:`), ticked after the loops.
        self.pump = PumpProbe(self.current)
        if daemon.machine is not None and daemon.machine.rule is not None:
            _wrap(daemon.machine, "tick", self.pump.timed(daemon.machine.tick))
        _wrap(pipeline, "feed", self._timed_feed(pipeline.feed))
        _wrap(pipeline, "send", self._timed_send(pipeline.send))
        _wrap(pipeline, "on_change", self._timed_change(pipeline.on_change))

    def _timed_feed(self, feed: Callable[[can.Message], None]) -> Callable[[can.Message], None]:
        def timed_feed(msg: can.Message) -> None:
            self.current["arrival"] = self.arrivals.popleft()
            feed(msg)

        return timed_feed

    def _timed_tick(self, k: int, tick: Callable[[np.ndarray], Tick]) -> Callable[..., Tick]:
        """Loop k's tick; the row's latency and CPU are taken at the last loop's."""
        current = self.current

        def timed_tick(row: np.ndarray) -> Tick:
            c0 = time.thread_time()
            out = tick(row)
            if current["stopping"]:  # the last row, ticked at shutdown: no frame completed it
                return out
            current["cpu"] += time.thread_time() - c0
            current["state_changed"] = out.state_changed
            current["row_changed"] = out.changed or (k > 0 and current["row_changed"])
            if k == self.last:
                self.latency.append(time.perf_counter() - current["arrival"])
                self.cpu.append(current["cpu"])
                current["cpu"] = 0.0
                self.row_t.append(out.t_s)
                if current["row_changed"]:
                    self.change_t.append(out.t_s)
            return out

        return timed_tick

    def _timed_send(self, send: Callable[[can.Message], None]) -> Callable[[can.Message], None]:
        def timed_send(msg: can.Message) -> None:
            if msg.arbitration_id in self.alarm_ids and self.current["state_changed"]:
                self.alarm_latency.append(time.perf_counter() - self.current["arrival"])
            send(msg)

        return timed_send

    def _timed_change(self, change: Callable[[Tick, Loop], None]) -> Callable[[Tick, Loop], None]:
        def timed_state_change(t: Tick, lp: Loop) -> None:
            # What a state change costs the detector thread (event log, black box, hook).
            w0, c0 = time.perf_counter(), time.thread_time()
            change(t, lp)
            self.change_wall.append(time.perf_counter() - w0)
            self.change_cpu.append(time.thread_time() - c0)

        return timed_state_change


def _put_on_bus(
    daemon: Daemon, channel: str, rec: Recording, dbc: Path, speed: float
) -> tuple[float, int]:
    """Start the daemon, send ``rec``'s frames with its timing at ``speed``, wait until the
    daemon decoded them all (at most 60 s more); (wall s of sending, frames sent)."""
    codec = FrameCodec.from_dbc(dbc)
    plan = _frames(codec, rec)
    sender = can.Bus(interface="virtual", channel=channel, preserve_timestamps=True)
    daemon.start()
    started = time.perf_counter()
    for t_s, name, values in plan:
        due = started + t_s / speed
        wait = due - time.perf_counter()
        if wait > 0:
            time.sleep(wait)
        sender.send(codec.encode_message(name, values, START_TIME_S + t_s))
    sent_s = time.perf_counter() - started
    deadline = time.monotonic() + 60.0
    while daemon.codec.counts.frames < len(plan) and time.monotonic() < deadline:
        time.sleep(0.05)
    sender.shutdown()
    return sent_s, len(plan)


def _tick_latencies(probe: _Probe) -> dict[str, Any]:
    """The rows' latency and CPU, apart near a state change (its event log fsync and
    black-box dump of the pre-alarm frames ran in the detector thread before the disk
    writer): within 2 s of data after it."""
    lat = np.array(probe.latency) * 1e3
    t_rows = np.array(probe.row_t)
    behind = np.zeros(lat.size, dtype=bool)
    for tc in probe.change_t:
        behind |= (t_rows >= tc) & (t_rows < tc + 2.0)
    steady = lat[~behind] if (~behind).any() else lat
    cpu = np.array(probe.cpu) * 1e3
    return {
        "ticks": int(lat.size),
        "tick_p50_ms": float(np.percentile(lat, 50)),
        "tick_p99_ms": float(np.percentile(lat, 99)),
        "tick_max_ms": float(lat.max()),
        "tick_p99_ms_away_from_state_changes": float(np.percentile(steady, 99)),
        "ticks_near_state_changes": int(behind.sum()),
        "tick_p99_ms_near_state_changes": float(np.percentile(lat[behind], 99))
        if behind.any()
        else None,
        "state_change_detector_ms": [float(v * 1e3) for v in probe.change_wall],
        "state_change_detector_cpu_ms": [float(v * 1e3) for v in probe.change_cpu],
        "tick_cpu_median_ms": float(np.median(cpu)),
        "tick_cpu_p99_ms": float(np.percentile(cpu, 99)),
        "alarm_frame_latency_ms": [float(v * 1e3) for v in probe.alarm_latency],
        # Where the slowest ticks were (row time s, latency ms): stalls cluster or not.
        "slowest_ticks": [(float(probe.row_t[i]), float(lat[i])) for i in np.argsort(lat)[-10:]],
        "ticks_over_1ms": int(np.count_nonzero(lat > 1.0)),
        **probe.pump.summary(cpu),
        "_latency_ms": lat,
        "_cpu_ms": cpu,
    }


def run(
    model: Path,
    horizon: int,
    seconds: float,
    speed: float,
    writes: str = "thread",
    loops: int = 1,
) -> dict[str, Any]:
    tmp = Path(tempfile.mkdtemp(prefix="monitor-bench-live-"))
    rec = test_recording(seconds, fault_at_s=0.6 * seconds)
    rec = Recording(rec.t, {k: v for k, v in rec.columns.items() if k != "RodPos"}, rec.source)
    channel = f"bench-{time.monotonic_ns()}"
    cfg = _config(model, horizon, loops, channel, tmp)
    if cfg.loops:
        rec = wide_recording(cfg, {lc.name: rec for lc in cfg.loops})
    arrivals: collections.deque[float] = collections.deque()
    bus = can.Bus(interface="virtual", channel=channel)
    daemon = Daemon(cfg, bus=_TimedBus(bus, arrivals))
    daemon.disk.writer.inline = writes == "inline"
    rss_loaded_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    probe = _Probe(daemon, arrivals)
    sent_s, frames = _put_on_bus(daemon, channel, rec, cfg.dbc, speed)
    probe.current["stopping"] = True
    daemon.stop()
    bus.shutdown()
    events = [json.loads(x) for x in (tmp / "events.jsonl").read_text().splitlines()]
    return {
        "model": str(model),
        "loops": len(daemon.loops),
        "writes": writes,
        "horizon": horizon,
        "seconds_of_data": seconds,
        "speed": speed,
        "wall_s": sent_s,
        "frames": frames,
        **_tick_latencies(probe),
        "state_changes": [e["state"] for e in events if "state" in e],  # not findings
        "dropped": daemon.counts()["dropped"],
        "disk_writer": daemon.disk.writer.counts.as_dict(),
        "black_box_files": len(list((tmp / "blackbox").glob("alarm-*.log"))),
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        "rss_after_load_mb": rss_loaded_kb / 1024.0,
    }


_SUMMARY = {
    "tick_p50_ms": ("lat", 50),
    "tick_p99_ms": ("lat", 99),
    "tick_max_ms": ("lat", 100),
    "tick_cpu_median_ms": ("cpu", 50),
    "tick_cpu_p99_ms": ("cpu", 99),
}


def compare(
    model: Path,
    horizon: int,
    seconds: float,
    speed: float,
    modes: list[str],
    rounds: int,
    loops: int = 1,
) -> dict[str, Any]:
    """``rounds`` daemons per write mode, alternating; latencies pooled per mode."""
    runs: dict[str, list[dict[str, Any]]] = {m: [] for m in modes}
    rss_mb = None
    for _ in range(rounds):
        for mode in modes:
            runs[mode].append(run(model, horizon, seconds, speed, mode, loops))
            rss_mb = rss_mb or runs[mode][-1]["peak_rss_mb"]
    out: dict[str, Any] = {}
    for mode, rs in runs.items():
        pooled = {
            "lat": np.concatenate([r.pop("_latency_ms") for r in rs]),
            "cpu": np.concatenate([r.pop("_cpu_ms") for r in rs]),
        }
        summary: dict[str, float | None] = {
            k: float(np.percentile(pooled[a], q)) for k, (a, q) in _SUMMARY.items()
        }
        summary["ticks"] = int(pooled["lat"].size)
        summary["ticks_over_1ms"] = int(np.count_nonzero(pooled["lat"] > 1.0))
        for key in ("state_change_detector_ms", "state_change_detector_cpu_ms"):
            values = [v for r in rs for v in r[key]]
            summary[key + "_median"] = float(np.median(values)) if values else None
        out[mode] = {**summary, "rounds": rs}
    first = modes[0]
    result = {**out[first]["rounds"][0], **{k: v for k, v in out[first].items() if k != "rounds"}}
    result.update({"peak_rss_mb": rss_mb, "modes": out, "rounds": rounds})
    if len(modes) == 2:
        a, b = modes
        result[f"ratio_{b}_over_{a}"] = {k: out[b][k] / out[a][k] for k in _SUMMARY}
    return result


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m monitor.bench.live", description=__doc__)
    ap.add_argument("--model", type=Path, required=True)
    ap.add_argument("--horizon", type=int, default=10)
    ap.add_argument("--seconds", type=float, default=600.0)
    ap.add_argument("--speed", type=float, default=5.0)
    ap.add_argument(
        "--writes",
        default="thread",
        help="thread, inline, or both comma-separated (default thread)",
    )
    ap.add_argument("--rounds", type=int, default=1, help="daemons per write mode (default 1)")
    ap.add_argument(
        "--loops",
        type=int,
        default=1,
        choices=(1, 4),
        help="loops in the daemon: 1 or 4 (config/excavator4.yaml)",
    )
    ap.add_argument("--json", type=Path, required=True)
    args = ap.parse_args(argv)
    modes = args.writes.split(",")
    if not set(modes) <= {"thread", "inline"} or args.rounds < 1:
        ap.error("--writes takes thread and/or inline; --rounds >= 1")
    result = compare(
        args.model, args.horizon, args.seconds, args.speed, modes, args.rounds, args.loops
    )
    args.json.write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    threading.current_thread().name = "bench-sender"
    sys.exit(main())
