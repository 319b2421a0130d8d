"""``monitor demo``: the shipped spool-wear log through a virtual CAN bus into the daemon.

The log (90 s of simulated boom cycles, spool wear of severity 0.6 from 45 s) is replayed
faster than real time onto a python-can ``virtual`` bus; the daemon's own code path (reader
thread, decoder, sampler, ticker, outputs) receives it, and a second bus node reads the
MON_Alarm frames back.  The sample clock is the log's, so the speed changes nothing but the
wall time.  ``--machine excavator4``: the whole machine's four loops on one bus instead
(``monitor.cli._demo_machine``).
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from monitor.cli._demo_machine import MACHINES, Scenario, machine_scenario, say_loops
from monitor.cli._paths import output_dir
from monitor.resources import resource_path

if TYPE_CHECKING:
    from monitor.bus.replay import ReplayCounts
    from monitor.config.settings import MonitorConfig
    from monitor.live.daemon import Daemon

DEMO_LOG = "spool_wear.log"
DEMO_ONSET_S = 45.0  # replay/regenerate.sh: --fault spool_wear:0.6@45
SPAN_S = 90.0  # the log's length


def add_subparser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "demo",
        help="replay the shipped fault log through a virtual CAN bus into the live monitor",
        description="Replays the shipped simulated spool-wear log (fault from 45 s) at "
        "--speed times real time onto a python-can virtual bus, runs the live monitor on it "
        "and prints alarms as they happen, a progress line and a summary. Under a minute.",
    )
    p.add_argument(
        "--speed",
        type=float,
        default=5.0,
        metavar="X",
        help="replay speed factor (default 5: the 90 s log in 18 s)",
    )
    p.add_argument(
        "--out",
        type=output_dir,
        default=None,
        metavar="DIR",
        help="keep the event log and black box here (default: a temp dir)",
    )
    p.add_argument(
        "--machine",
        choices=MACHINES,
        default=None,
        help="the whole machine instead (excavator4: boom, stick, bucket and swing on one "
        "bus, the daemon with config/excavator4.yaml's four loops, the stick's spool worn "
        "from 45 s; the log is simulated first)",
    )
    p.set_defaults(func=run)


class _Progress:
    def __init__(self, tty: bool) -> None:
        self.tty = tty
        self.last_wall = 0.0
        self.last_t = -10.0

    def show(
        self, daemon: Daemon, counts: ReplayCounts, span_s: float, force: bool = False
    ) -> None:
        now = time.monotonic()
        t = (counts.last_ts or 0.0) - (counts.first_ts or 0.0)
        if self.tty:
            if not force and now - self.last_wall < 0.25:
                return
        elif not force and t - self.last_t < 10.0:
            return
        self.last_wall, self.last_t = now, t
        line = (
            f"  log {t:5.1f}/{span_s:.0f} s  state {daemon.state.label:<12} "
            f"{_levels(daemon)}  frames {daemon.reader.counts.received}"
        )
        print(("\r" + line) if self.tty else line, end="" if self.tty else "\n", flush=True)


def _levels(daemon: Daemon) -> str:
    """The alarm level and J's share of it: the alarm is raised above 1, by J or by B;
    with several loops, each loop's level."""
    if len(daemon.loops) > 1:
        return "levels " + " ".join(
            f"{lp.name} {'n/a' if lp.last_level != lp.last_level else f'{lp.last_level:.2f}'}"
            for lp in daemon.loops
        )
    lp = daemon.loops[0]
    j, level = lp.last_j, lp.last_level
    if level != level:
        return "level n/a, J warming"
    return f"level {level:.2f}, J/eps0 {j / lp.model.eps0:.2f}"


def run(args: argparse.Namespace) -> int:
    if not args.speed > 0:
        print("monitor demo: error: --speed must be > 0", file=sys.stderr)
        return 2
    logger = logging.getLogger("monitor")
    level = logger.level
    # The demo prints its own lines; the daemon's journal lines would interleave with them.
    logger.setLevel(logging.ERROR)
    try:
        with tempfile.TemporaryDirectory(prefix="monitor-demo-") as tmp:
            if args.machine:
                scenario = machine_scenario(Path(tmp))
            else:
                log_path = resource_path("replay", DEMO_LOG)
                scenario = Scenario(log_path, None, DEMO_ONSET_S, SPAN_S, "spool wear")
            return _demo(scenario, args.out or Path(tmp), args.speed, kept=args.out is not None)
    finally:
        logger.setLevel(level)


def _demo(scenario: Scenario, out: Path, speed: float, kept: bool) -> int:
    from monitor.live.daemon import Daemon

    channel = f"monitor-demo-{os.getpid()}"
    cfg = _demo_config(out, channel, scenario)
    tty = sys.stdout.isatty()
    alarms: list[dict[str, Any]] = []

    def on_event(ev: dict[str, Any]) -> None:
        if tty:
            print("\r" + " " * 100 + "\r", end="")
        if ev.get("kind") == "finding":  # the machine's finding (several loops)
            print(f"[log t={ev['t']:6.2f} s] machine finding: {ev['named'] or 'none'}", flush=True)
            return
        fault = f", isolated: {ev['fault']}" if ev["fault"] else ""
        loop = f"{ev['loop']}: " if "loop" in ev else ""
        print(
            f"[log t={ev['t']:6.2f} s] {loop}state -> {ev['state'].upper()} "
            f"({_levels(daemon)}{fault})",
            flush=True,
        )
        if ev["state"] == "fault":
            alarms.append(ev)

    print(
        f"monitor demo: replaying {scenario.log.name} ({scenario.what} from "
        f"{scenario.onset_s:.0f} s) at {speed:g}x real time on virtual CAN bus {channel!r}"
    )
    daemon = Daemon(cfg, on_event=on_event)
    readback = _AlarmReadback(cfg, daemon)
    start = time.monotonic()
    counts = _replay(daemon, readback, scenario, speed, _Progress(tty))
    c = daemon.counts()
    span = scenario.span_s
    print(f"\nsummary ({time.monotonic() - start:.1f} s wall for {span:.0f} s of log):")
    t0 = counts.first_ts or 0.0
    if len(daemon.loops) > 1:
        say_loops([lp.name for lp in daemon.loops], alarms, readback.frames, t0, scenario)
    else:
        _say_alarm(alarms)
        _say_frames(readback.frames, t0)
    print(
        f"  frames: {c['received']} received, {c['decoded']} decoded, "
        f"{sum(c['rejected'].values())} rejected, {c['dropped']} dropped; {c['ticks']} ticks"
    )
    if kept:
        print(f"  event log: {cfg.event_log.path}; black box: {cfg.black_box.directory}")
    else:
        print(
            "  event log and black box were written to a temporary folder, removed on exit "
            "(keep them with --out DIR)"
        )
    return 0


def _demo_config(out: Path, channel: str, scenario: Scenario) -> MonitorConfig:
    """The scenario's config on a virtual bus of its own, the outputs written under
    ``out``."""
    from monitor.bus.reader import BusConfig
    from monitor.config.settings import load_config

    cfg = load_config(scenario.config)
    # The queue holds the whole log: a slow first tick must not cost frames.
    queue = max(100_000, scenario.frames + 1000)
    return dataclasses.replace(
        cfg,
        bus=BusConfig(interface="virtual", channel=channel, silent_s=2.0, queue_frames=queue),
        event_log=dataclasses.replace(cfg.event_log, path=out / "events.jsonl"),
        black_box=dataclasses.replace(cfg.black_box, directory=out / "blackbox"),
    )


class _AlarmReadback:
    """Another node on the demo's bus, reading the daemon's MON_Alarm frames back (every
    loop's alarm message): (bus time, state, fault name, loop) each.  Its own codec, so the
    daemon's counters stay its own."""

    def __init__(self, cfg: MonitorConfig, daemon: Daemon) -> None:
        import can

        from monitor.codec.frames import FrameCodec
        from monitor.live.outputs import ALARM, fault_codes

        self.bus = can.Bus(interface="virtual", channel=cfg.bus.channel)
        self.codec = FrameCodec.from_dbc(cfg.dbc)
        names = [lc.alarm_message for lc in cfg.monitored_loops] if cfg.loops else [ALARM]
        loops = [lc.name for lc in cfg.monitored_loops]
        # Frame id -> (loop, fault code -> name of that loop's message's value table).
        self.alarm_ids = {
            self.codec.message(n).frame_id: (
                loop,
                {code: f for f, code in fault_codes(daemon.codec, n).items()},
            )
            for n, loop in zip(names, loops, strict=True)
        }
        self.frames: list[tuple[float, int, str, str]] = []
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._listen, name="demo-listener", daemon=True)

    def _listen(self) -> None:
        while not self.stop.is_set():
            m = self.bus.recv(0.1)
            if m is not None and m.arbitration_id in self.alarm_ids:
                d = self.codec.decode_message(m)
                if d.values is not None:
                    loop, codes = self.alarm_ids[m.arbitration_id]
                    fault = codes.get(int(d.values["Fault"]), "?")
                    self.frames.append((m.timestamp, int(d.values["State"]), fault, loop))

    def close(self) -> None:
        self.stop.set()
        self.thread.join(2.0)
        self.bus.shutdown()


def _replay(
    daemon: Daemon, readback: _AlarmReadback, scenario: Scenario, speed: float, progress: _Progress
) -> ReplayCounts:
    """The log onto the bus at ``speed`` with the daemon and the read-back running; both
    stopped after it, in order."""
    import can

    from monitor.bus.replay import replay_log

    sender = can.Bus(interface="virtual", channel=daemon.cfg.bus.channel, preserve_timestamps=True)
    readback.thread.start()
    daemon.start()
    try:
        counts = replay_log(
            scenario.log,
            sender,
            speed,
            on_frame=lambda m, c: progress.show(daemon, c, scenario.span_s),
        )
        _drain(daemon)
    finally:
        daemon.stop()
        time.sleep(0.2)
        readback.close()
        sender.shutdown()
    progress.show(daemon, counts, scenario.span_s, force=True)
    if progress.tty:
        print()
    return counts


def _drain(daemon: Daemon, timeout_s: float = 600.0) -> None:
    """Wait until the detector has decoded every frame the reader took off the bus (on a
    busy machine it runs far behind a fast replay; stopping it early would lose the end)."""
    deadline = time.monotonic() + timeout_s
    settled = 0
    while time.monotonic() < deadline and daemon.healthy and settled < 3:
        r = daemon.reader.counts
        done = daemon.reader.queue.empty() and daemon.codec.counts.frames >= r.received - r.dropped
        settled = settled + 1 if done else 0
        time.sleep(0.1)


def _say_alarm(alarms: list[dict[str, Any]]) -> None:
    if not alarms:
        print("  no hydraulic fault raised")
        return
    first = alarms[0]
    print(
        f"  hydraulic fault raised at {first['t']:.2f} s of the log, "
        f"{first['t'] - DEMO_ONSET_S:.2f} s after the fault's onset at {DEMO_ONSET_S:.0f} s;"
        f" isolated: {first['fault']}"
    )


def _say_frames(frames: list[tuple[float, int, str, str]], t0: float) -> None:
    fault_frames = [f for f in frames if f[1] == 1]
    if fault_frames:
        print(
            f"  MON_Alarm frames read back off the bus: {len(frames)} "
            f"({len(fault_frames)} in fault, first at {fault_frames[0][0] - t0:.2f} s, "
            f"fault {fault_frames[0][2]})"
        )
    else:
        print(f"  MON_Alarm frames read back off the bus: {len(frames)}")
