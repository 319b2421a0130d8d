"""Field conditions: `monitor run` and `monitor replay` as separate processes on python-can's
`udp_multicast` bus, with the config of the hardware-free recipe as the docs write it
(docs/how-to/try-without-hardware.md), and with a
CPU hog busy on every core.  The daemon must give the events `monitor detect` gives for the
same log: one alarm episode with the same fault, no `inactive` while the engine runs.

The soak: normal operation replayed at 2x (the fastest the sampler honours: bus.time_scale
0.5) with the hogs on must add no episode at all.  CI replays two minutes of it;
MONITOR_FIELD_SOAK=1 replays an hour (about 35 min).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from live_support import REPO, own_udp_port, start_daemon, wait_for_text

from monitor.config.settings import load_config
from monitor.detection.offline import detect
from monitor.model.modelfile import load_model
from monitor.resources import resource_path
from monitor.sampling.read import read_recording

LOG = resource_path("replay", "spool_wear.log")


def _multicast_works() -> str | None:
    try:
        import can

        bus = can.Bus(interface="udp_multicast", channel="239.74.163.9", port=43199)
        bus.shutdown()
    except Exception as exc:  # noqa: BLE001 - any failure means: not on this host
        return f"python-can udp_multicast unavailable here: {exc}"
    return None


pytestmark = pytest.mark.skipif(_multicast_works() is not None, reason=str(_multicast_works()))


# The daemon shares the controller's CPU with the hogs (same priority); the replayer plays
# the sensor ECUs, which have CPUs of their own on a machine, so it runs ahead of both: a
# starved replayer would put real gaps on the bus, and a monitor must call those silence.
CONTROLLER_NICE = 5


def _hogs() -> list[subprocess.Popen]:
    """One busy process per core, at the same priority as the monitor."""
    return [
        subprocess.Popen(
            [sys.executable, "-c", "while True: pass"], preexec_fn=lambda: os.nice(CONTROLLER_NICE)
        )
        for _ in range(os.cpu_count() or 2)
    ]


RECIPE = REPO / "docs" / "how-to" / "try-without-hardware.md"


def recipe_config() -> str:
    """The `try.yaml` of the documented recipe, as written there."""
    lines = RECIPE.read_text().splitlines()
    start = next(i for i, x in enumerate(lines) if x.startswith("    bus:"))
    block = []
    for x in lines[start:]:
        if not x.startswith("    "):
            break
        block.append(x[4:])
    return "\n".join(block) + "\n"


class BusLog:
    """What was on the bus, as a candump log: every frame with its arrival time (the kernel's
    stamp, as the daemon gets it; times scaled back by ``speed``), but the monitor's own
    (source address 0xA0).  A replayer starved of CPU
    puts real gaps on the bus; the daemon must then agree with `monitor detect` of this log."""

    def __init__(self, channel: str, port: int, speed: float) -> None:
        from monitor.bus.reader import BusConfig, open_bus

        self.bus = open_bus(
            BusConfig(interface="udp_multicast", channel=channel, options={"port": port})
        )
        self.speed, self.frames, self._stop = speed, [], threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            m = self.bus.recv(0.1)
            if m is not None and not m.is_error_frame and (m.arbitration_id & 0xFF) != 0xA0:
                self.frames.append(m)

    def write(self, path: Path) -> Path:
        self._stop.set()
        self._thread.join()
        self.bus.shutdown()
        t0 = self.frames[0].timestamp
        with path.open("w") as out:
            for m in self.frames:
                t = t0 + (m.timestamp - t0) * self.speed
                ident = f"{m.arbitration_id:08X}" if m.is_extended_id else f"{m.arbitration_id:03X}"
                out.write(f"({t:.6f}) can0 {ident}#{m.data.hex().upper()}\n")
        return path


def _caught_up(events: Path, listener: BusLog, daemon: subprocess.Popen) -> None:
    """Wait (bounded, not a threshold) until the daemon has judged the bus up to its last
    frame: the silence after it makes an event past it, unless the state was already
    inactive.  A SIGTERM earlier stops the reader with frames still in its socket."""
    import time

    end = (listener.frames[-1].timestamp - listener.frames[0].timestamp) * listener.speed
    deadline = time.monotonic() + 120.0
    while time.monotonic() < deadline and daemon.poll() is None:
        lines = events.read_text().splitlines() if events.exists() else []
        if any(json.loads(x).get("t", -1.0) >= end for x in lines if x.strip()):
            return
        time.sleep(0.2)


def _field_run(tmp_path: Path, log: Path, speed: float, channel: str) -> list[dict]:
    """The daemon's state-change events for ``log`` replayed from another process, with the
    recipe's config (and ``channel``; bus.time_scale 1/speed for a faster replay); what
    was on the bus is written to ``tmp_path/bus.log``."""
    text = recipe_config().replace("239.74.163.2", channel)
    if speed != 1.0:
        text = text.replace("}", f", time_scale: {1.0 / speed}}}", 1)
    config = tmp_path / "try.yaml"
    config.write_text(text)
    daemon_log = tmp_path / "daemon.log"
    udp_port = own_udp_port()
    port = {"CAN_CONFIG": json.dumps({"port": udp_port})}  # python-can reads it
    hogs = _hogs()
    listener = None
    daemon = start_daemon(config, tmp_path, daemon_log, env=port, nice=CONTROLLER_NICE)
    try:
        wait_for_text(daemon_log, "monitoring", daemon, 120.0)
        # The daemon says how long it took to start and what numba's cache gave.
        wait_for_text(daemon_log, "loaded from the cache", daemon, 60.0)
        env = {**os.environ, "PYTHONPATH": str(REPO), **port}
        listener = BusLog(channel, udp_port, speed)
        replay = subprocess.run(
            [
                sys.executable,
                "-m",
                "monitor",
                "replay",
                str(log),
                "--bus",
                channel,
                "--interface",
                "udp_multicast",
                "--speed",
                str(speed),
            ],
            capture_output=True,
            text=True,
            env=env,
            timeout=7200,
            check=False,
        )
        assert replay.returncode == 0, replay.stderr
        if listener is not None:
            _caught_up(tmp_path / "events.jsonl", listener, daemon)
    finally:
        for h in hogs:
            h.kill()
        daemon.send_signal(signal.SIGTERM)
        daemon.wait(60)
        if listener is not None:
            listener.write(tmp_path / "bus.log")
    lines = [json.loads(x) for x in (tmp_path / "events.jsonl").read_text().splitlines()]
    return [e for e in lines if e.get("kind") != "bus"]


def _shape(events: list[dict], end_t: float, settled_t: float = 0.05) -> list[tuple]:
    """What must agree: the state in force once the first frames of every message are in
    (``settled_t``; over the bus they arrive microseconds apart, in a log at one instant)
    and every change after it, with fault and gating keys, up to the log's last sample
    (after it the daemon rightly sees the bus fall silent)."""
    keys = ("state", "fault", "op_state", "out_of_range_signal", "sensor", "sensor_check")
    first = [e for e in events if e["t"] <= settled_t][-1:]
    later = [e for e in events if settled_t < e["t"] <= end_t]
    return [tuple(e[k] for k in keys) for e in first + later]


def test_daemon_and_replayer_apart_with_hogs_give_the_desks_events(tmp_path: Path) -> None:
    cfg = load_config()
    rec = read_recording(LOG)
    offline = detect(load_model(cfg.model), rec, cfg.alarm, cfg.horizon, gating=cfg.gating)
    live = _field_run(tmp_path, LOG, speed=1.0, channel="239.74.163.5")
    assert [e["state"] for e in offline.events] == ["normal", "fault"]  # the log's story
    bus, end_bus = _desk(tmp_path / "bus.log", cfg)
    assert _shape(live, end_bus) == _shape(bus.events, end_bus)
    boxes = list((tmp_path / "blackbox").glob("*"))
    assert len(boxes) == bus.summary["alarm_episodes"]  # one black box per episode
    if "inactive" not in [e["state"] for e in bus.events]:  # the replayer kept time
        end_t = float(rec.t[-1] - rec.t[0]) - 0.05
        assert _shape(live, end_t) == _shape(offline.events, end_t)
        assert len(boxes) == 1  # one fault, one episode, one black box


def _desk(bus_log: Path, cfg):  # noqa: ANN202 - (Detection, end time)
    """`monitor detect` of what was on the bus, and the time of its last sample."""
    rec = read_recording(bus_log)
    det = detect(load_model(cfg.model), rec, cfg.alarm, cfg.horizon, gating=cfg.gating)
    return det, float(rec.t[-1] - rec.t[0]) - 0.05


SOAK_S = 3600.0 if os.environ.get("MONITOR_FIELD_SOAK") else 120.0


def test_soak_of_normal_operation_at_the_fastest_speed_adds_no_episode(tmp_path: Path) -> None:
    from monitor.codec.logwrite import write_candump
    from monitor.sim.cycles import make_cycle
    from monitor.sim.machine import load_machine
    from monitor.sim.simulate import simulate

    log = tmp_path / "hour.log"
    write_candump(log, simulate(make_cycle("boom", SOAK_S, 9191), load_machine(), seed=9191))
    cfg = load_config()
    rec = read_recording(log)
    offline = detect(load_model(cfg.model), rec, cfg.alarm, cfg.horizon, gating=cfg.gating)
    live = _field_run(tmp_path, log, speed=2.0, channel="239.74.163.6")
    assert offline.summary["alarm_episodes"] == 0
    bus, end_bus = _desk(tmp_path / "bus.log", cfg)
    assert _shape(live, end_bus) == _shape(bus.events, end_bus)
    assert live_episodes(live) == bus.summary["alarm_episodes"] == 0  # no episode added
    assert not list((tmp_path / "blackbox").glob("*"))  # no black box
    if "inactive" not in [e["state"] for e in bus.events]:  # the replayer kept time
        # Inactive only after the log ends (the bus falls silent), never while it runs.
        assert "inactive" not in [e["state"] for e in live][:-1]
        end_t = float(rec.t[-1] - rec.t[0]) - 0.05
        assert _shape(live, end_t) == _shape(offline.events, end_t)


def live_episodes(events: list[dict]) -> int:
    """Alarm episodes in an event log: entries into the fault state from outside an episode
    (after a normal state; a gap's return to fault is the same episode)."""
    n, last = 0, None
    for e in events:
        if e["state"] == "fault" and last == "normal":
            n += 1
        if e["state"] in ("fault", "normal"):
            last = e["state"]
    return n
