"""The controller's install measured from outside: disk of its environment, and `monitor run`
from it (start-up, RSS) replaying a shipped log over `udp_multicast`, its events beside
`monitor detect`'s of the same log.

    python benchmarks/controller_install.py VENV [--runs 3] [--log spool_wear.log]

VENV is a virtual environment with the monitor installed (e.g. the wheel of `monitor
build-controller`); every process runs that environment's Python.  Prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

_READY = re.compile(r"ready (\d+\.\d+) s after the start")

# The daemon's code path in-process on a python-can virtual bus, the log replayed as fast as
# it is taken with its own timestamps (as the tests do): events that do not depend on the load.
_VIRTUAL = """
import dataclasses, json, sys, time
import can
from monitor.bus.replay import replay_log
from monitor.config.settings import BusConfig, load_config
from monitor.live.daemon import Daemon
cfg = load_config()
cfg = dataclasses.replace(
    cfg,
    bus=BusConfig(interface="virtual", channel="ctl", queue_frames=200_000, silent_s=30.0),
    outputs=dataclasses.replace(cfg.outputs, frames_max_per_s=1e6),
    event_log=dataclasses.replace(cfg.event_log, path=sys.argv[2] + "/events.jsonl"),
    black_box=dataclasses.replace(cfg.black_box, directory=sys.argv[2] + "/bb"),
)
events = []
daemon = Daemon(cfg, on_event=events.append)
daemon.start()
sender = can.Bus(interface="virtual", channel="ctl", preserve_timestamps=True)
sent = replay_log(sys.argv[1], sender, speed=None).sent
while daemon.codec.counts.frames < sent - daemon.reader.counts.dropped:
    time.sleep(0.05)
daemon.stop()
sender.shutdown()
print(json.dumps({"numba": "numba" in sys.modules, "events": events}))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("venv", type=Path)
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--log", default="spool_wear.log", help="a log shipped in replay/")
    ap.add_argument(
        "--daemon-nice", type=int, default=5, help="niceness of `monitor run` (the replayer: -10)"
    )
    args = ap.parse_args()
    args.venv = args.venv.resolve()
    py = str(args.venv / "bin" / "python")
    os.chdir(tempfile.gettempdir())  # not a source tree: its `monitor` would come first
    log = subprocess.run(
        [
            py,
            "-c",
            f"from monitor.resources import resource_path as r; print(r('replay', {args.log!r}))",
        ],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    out: dict[str, Any] = {"venv": str(args.venv), "log": args.log, **_disk(args.venv, py)}
    out["numba_importable"] = (
        subprocess.run([py, "-c", "import numba"], capture_output=True).returncode == 0
    )
    with tempfile.TemporaryDirectory(prefix="controller-") as tmp:
        detect = _detect(py, log, Path(tmp))
        virtual = json.loads(
            subprocess.run(
                [py, "-c", _VIRTUAL, log, tmp], capture_output=True, text=True, check=True
            ).stdout.splitlines()[-1]
        )
        runs = [
            _run(py, log, Path(tmp) / f"run{i}", 43300 + i, args.daemon_nice)
            for i in range(args.runs)
        ]
    out["detect_state_events"] = detect
    for key in ("spawn_to_ready_s", "ready_line_s", "rss_median_mb", "rss_peak_mb"):
        out[key] = [r[key] for r in runs]
        out[f"{key}_median"] = statistics.median(out[key])
    out["numba_loaded_by_run"] = [r["numba_loaded"] for r in runs]
    out["virtual_bus_events_equal_detect"] = _states_of(virtual["events"]) == detect
    out["virtual_bus_numba_loaded"] = virtual["numba"]
    out["events_equal_detect"] = [r["events"] == detect for r in runs]
    out["run_state_events"] = [r["events"] for r in runs if r["events"] != detect]
    out["load"] = os.getloadavg()
    print(json.dumps(out, indent=1))


def _disk(venv: Path, py: str) -> dict[str, Any]:
    site = Path(
        subprocess.run(
            [py, "-c", "import sysconfig; print(sysconfig.get_paths()['platlib'])"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    )
    tops = {p.name: _size(p) for p in site.iterdir() if p.is_dir() and not p.name.endswith("-info")}
    biggest = sorted(tops.items(), key=lambda kv: -kv[1])[:6]
    return {
        "venv_mb": _size(venv) / 1e6,
        "site_packages_mb": _size(site) / 1e6,
        "biggest_mb": {k: round(v / 1e6, 1) for k, v in biggest},
        "packages": len(list(site.glob("*.dist-info"))),
    }


def _size(path: Path) -> int:
    return sum(f.lstat().st_size for f in path.rglob("*") if f.is_file() and not f.is_symlink())


def _states(path: Path, t_end: float | None = None) -> list[list[Any]]:
    """(t, state, fault) of the state changes, up to ``t_end`` (the log's last frame)."""
    return _states_of([json.loads(x) for x in path.read_text().splitlines() if x.strip()], t_end)


def _states_of(rows: list[dict[str, Any]], t_end: float | None = None) -> list[list[Any]]:
    return [
        [e["t"], e["state"], e["fault"]]
        for e in rows
        if e.get("event", "state") == "state" and (t_end is None or e["t"] <= t_end + 1e-6)
    ]


def _detect(py: str, log: str, tmp: Path) -> list[list[Any]]:
    events = tmp / "detect.jsonl"
    subprocess.run(
        [py, "-m", "monitor", "detect", log, "--events", str(events), "--j-every", "0"],
        capture_output=True,
        check=True,
    )
    return _states(events)


def _run(py: str, log: str, work: Path, port: int, nice: int) -> dict[str, Any]:
    """`monitor run` (niced ``nice``; the how-to advises 5 on a busy computer) on a
    udp_multicast group and port of its own; the log replayed in real time once the daemon is
    ready; RSS every 0.2 s."""
    work.mkdir()
    group = "239.74.171.9"
    config = work / "monitor.yaml"
    config.write_text(
        f'bus: {{interface: udp_multicast, channel: "{group}", '
        f"options: {{port: {port}}}}}\n"
        f"event_log: {{path: {work / 'events.jsonl'}}}\nblack_box: {{directory: {work / 'bb'}}}\n"
    )
    err = work / "daemon.log"
    env = {**os.environ, "CAN_CONFIG": json.dumps({"port": port})}
    t0 = time.perf_counter()
    with err.open("wb") as fh:
        proc = subprocess.Popen(
            ["nice", "-n", str(nice), py, "-m", "monitor", "run", "--config", str(config)],
            stderr=fh,
            stdin=subprocess.DEVNULL,
            cwd=work,
            env=env,
        )
    while not (m := _READY.search(err.read_text(errors="replace"))):
        if proc.poll() is not None or time.perf_counter() - t0 > 60:
            raise SystemExit(f"monitor run did not get ready:\n{err.read_text()[-2000:]}")
        time.sleep(0.005)
    spawn_to_ready = time.perf_counter() - t0
    feed = subprocess.Popen(
        [
            # at bus priority (the sensors do not wait for the CPU): a starved replayer
            # really leaves the bus silent, and the daemon rightly says so (inactive, stale)
            *("nice", "-n", "-10"),
            py,
            "-m",
            "monitor",
            "replay",
            log,
            "--bus",
            group,
            "--interface",
            "udp_multicast",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=env,
    )
    samples = []
    while feed.poll() is None:
        samples.append(_status(proc.pid, "VmRSS"))
        time.sleep(0.2)
    time.sleep(2.0)  # the detector drains what the reader holds
    peak = _status(proc.pid, "VmHWM")
    maps = Path(f"/proc/{proc.pid}/maps").read_text()
    proc.terminate()
    proc.wait(30)
    t_end = _last_frame_t(log)
    return {
        "spawn_to_ready_s": spawn_to_ready,
        "ready_line_s": float(m.group(1)),
        "rss_median_mb": statistics.median(samples[len(samples) // 2 :]),
        "rss_peak_mb": peak,
        "numba_loaded": "llvmlite" in maps or "numba" in maps,
        "events": _states(work / "events.jsonl", t_end),
    }


def _last_frame_t(log: str) -> float:
    lines = [x for x in Path(log).read_text().splitlines() if x.startswith("(")]
    first, last = (float(x[1 : x.index(")")]) for x in (lines[0], lines[-1]))
    return last - first


def _status(pid: int, key: str) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(f"{key}:"):
            return float(line.split()[1]) / 1024.0  # kB
    raise RuntimeError(f"{key} not in /proc/{pid}/status")


if __name__ == "__main__":
    main()
