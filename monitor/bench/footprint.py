"""What a controller engineer asks first: how long `monitor --help` takes, how long the daemon
takes from process start to its first tick (with numba's cache warm, and empty), and how much
memory the daemon process holds alone (steady, peak, growth) while a replayer in another
process feeds it the shipped log over python-can's `udp_multicast` bus, and what `monitor
detect` of a shipped log takes (wall, peak RSS); the daemon and detect figures with the
kernels compiled ahead of time and, side by side, with numba's JIT.
"""

from __future__ import annotations

import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from monitor.resources import resource_path

# VmHWM of this process's own memory (ru_maxrss would carry the parent's peak across fork).
_HELP_PROBE = """
import runpy, sys, time
t0 = time.perf_counter()
sys.argv = ["monitor", "--help"]
try:
    runpy.run_module("monitor", run_name="__main__")
except SystemExit:
    pass
hwm = next(x for x in open("/proc/self/status") if x.startswith("VmHWM:")).split()[1]
print(time.perf_counter() - t0, hwm, file=sys.stderr)
"""
# `monitor detect` of a shipped log in its own process: wall, peak RSS, numba loaded or not.
_DETECT_PROBE = """
import runpy, sys, time
t0 = time.perf_counter()
sys.argv = ["monitor", "detect", sys.argv[1], "--j-every", "0"]
try:
    runpy.run_module("monitor", run_name="__main__")
except SystemExit:
    pass
hwm = next(x for x in open("/proc/self/status") if x.startswith("VmHWM:")).split()[1]
print(time.perf_counter() - t0, hwm, int("numba" in sys.modules), file=sys.stderr)
"""
_FIRST_TICK = re.compile(r"t=\d+\.\d+ s: ")


def cli_help(runs: int = 5) -> dict[str, float]:
    """Median wall time of a whole `monitor --help` process, and its peak RSS."""
    walls, rss = [], []
    for _ in range(runs):
        t0 = time.perf_counter()
        out = subprocess.run(
            [sys.executable, "-c", _HELP_PROBE], capture_output=True, text=True, check=True
        )
        walls.append(time.perf_counter() - t0)
        rss.append(float(out.stderr.split()[-1]) / 1024.0)  # kB
    return {"cli_help_s": statistics.median(walls), "cli_help_rss_mb": max(rss)}


def daemon(
    seconds: float,
    say: Callable[[str], None],
    group: str = "239.74.163.11",
    warm_cache: Path | None = None,
) -> dict:
    """The daemon alone in its process: start to first tick (empty numba cache, then after
    ``monitor warm-up``, or with ``warm_cache``, a cache it filled before), then steady and
    peak RSS over ``seconds`` of the shipped normal log replayed in a loop, each with the
    tick kernels compiled ahead of time and, side by side, with numba's JIT
    (``MONITOR_AOT=0``)."""
    work = Path(tempfile.mkdtemp(prefix="monitor-footprint-"))
    config = work / "monitor.yaml"
    config.write_text(
        f'bus: {{interface: udp_multicast, channel: "{group}"}}\n'
        f"event_log: {{path: {work / 'events.jsonl'}}}\n"
        f"black_box: {{directory: {work / 'bb'}}}\n"
    )
    out: dict[str, Any] = {}
    say("footprint: daemon start, empty numba cache")
    out["first_run_s"] = _start(config, work, group, 20.0, {"NUMBA_CACHE_DIR": str(work / "c")})
    warm = {"NUMBA_CACHE_DIR": str(warm_cache or work / "w")}
    out["warm_up_s"] = None
    if warm_cache is None:
        say("footprint: monitor warm-up (numba cache and the kernels ahead of time)")
        t0 = time.perf_counter()
        subprocess.run(
            [sys.executable, "-m", "monitor", "warm-up"],
            env=_env(warm),
            check=True,
            capture_output=True,
        )
        out["warm_up_s"] = time.perf_counter() - t0
    else:
        say(f"footprint: the numba cache {warm_cache}, warmed before (warm_up_s not measured)")
    for tag, extra in (("", warm), ("_jit", {**warm, "MONITOR_AOT": "0"})):
        kind = "JIT" if tag else "ahead of time"
        say(f"footprint: monitor detect of the shipped spool-wear log ({kind})")
        out.update({f"{k}{tag}": v for k, v in _detect(extra).items()})
        say(f"footprint: daemon start, warm cache, kernels {kind}")
        out[f"daemon_start{tag}_s"] = _start(config, work, group, 20.0, extra)
        say(f"footprint: daemon RSS over {seconds:.0f} s of the shipped normal log ({kind})")
        out.update(
            {
                f"{k}{tag}" if tag else k: v
                for k, v in _rss(config, work, group, seconds, extra).items()
            }
        )
    return out


def _detect(extra: dict[str, str], runs: int = 3) -> dict[str, float]:
    """`monitor detect replay/spool_wear.log`, ``runs`` processes: median wall, peak RSS."""
    log = resource_path("replay", "spool_wear.log")
    walls, rss, numba = [], [], []
    for _ in range(runs):
        done = subprocess.run(
            [sys.executable, "-c", _DETECT_PROBE, str(log)],
            env=_env(extra),
            capture_output=True,
            text=True,
            check=True,
        )
        wall, hwm, loaded = done.stderr.split()[-3:]
        walls.append(float(wall))
        rss.append(float(hwm) / 1024.0)  # kB
        numba.append(float(loaded))
    return {
        "detect_s": statistics.median(walls),
        "detect_rss_mb": max(rss),
        "detect_numba_loaded": max(numba),
    }


def _env(extra: dict[str, str]) -> dict[str, str]:
    repo = Path(__file__).resolve().parents[2]
    return {**os.environ, "PYTHONPATH": str(repo), **extra}


def _replayer(group: str, log: Path, env: dict[str, str]) -> subprocess.Popen:
    return subprocess.Popen(
        [
            sys.executable,
            "-m",
            "monitor",
            "replay",
            str(log),
            "--bus",
            group,
            "--interface",
            "udp_multicast",
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=env,
    )


def _daemon(config: Path, work: Path, env: dict[str, str]) -> tuple[subprocess.Popen, Path]:
    err = work / f"daemon-{time.monotonic_ns()}.log"
    with err.open("wb") as fh:
        proc = subprocess.Popen(
            [sys.executable, "-m", "monitor", "run", "--config", str(config)],
            stderr=fh,
            stdin=subprocess.DEVNULL,
            cwd=work,
            env=env,
        )
    return proc, err


def _start(config: Path, work: Path, group: str, timeout_s: float, extra: dict) -> float | None:
    """Seconds from starting the process to its first tick (its first state line), with a
    replayer sending the shipped log from the same moment."""
    env = _env(extra)
    t0 = time.perf_counter()
    proc, err = _daemon(config, work, env)
    feed = _replayer(group, resource_path("replay", "normal.log"), env)
    try:
        while time.perf_counter() - t0 < timeout_s + 60.0 and proc.poll() is None:
            if _FIRST_TICK.search(err.read_text(errors="replace")):
                return time.perf_counter() - t0
            time.sleep(0.01)
        return None
    finally:
        for p in (feed, proc):
            p.terminate()
            p.wait(30)


def _rss(config: Path, work: Path, group: str, seconds: float, extra: dict) -> dict[str, float]:
    """RSS samples every 0.5 s while the shipped normal log is replayed again and again for
    ``seconds``: steady (median of the second half), peak (VmHWM) and growth (median of the
    last tenth minus that of the second tenth: a leak shows there on a long run)."""
    env = _env(extra)
    proc, err = _daemon(config, work, env)
    try:
        while not _FIRST_TICK.search(err.read_text(errors="replace")) and proc.poll() is None:
            # start the replayer only once the daemon listens: every frame is taken
            if "monitoring" in err.read_text(errors="replace"):
                break
            time.sleep(0.05)
        feed = _replayer(group, resource_path("replay", "normal.log"), env)
        samples = []
        end = time.perf_counter() + seconds
        while time.perf_counter() < end and proc.poll() is None:
            if feed.poll() is not None:  # the log ended: again, for as long as asked
                feed = _replayer(group, resource_path("replay", "normal.log"), env)
            samples.append(_status_kb(proc.pid, "VmRSS") / 1024.0)
            time.sleep(0.5)
        peak = _status_kb(proc.pid, "VmHWM") / 1024.0
        feed.terminate()
        feed.wait(30)
    finally:
        proc.terminate()
        proc.wait(30)
    second_half = samples[len(samples) // 2 :] or samples
    tenth = max(1, len(samples) // 10)
    growth = statistics.median(samples[-tenth:]) - statistics.median(
        samples[tenth : 2 * tenth] or samples
    )
    return {
        "daemon_rss_mb": statistics.median(second_half),
        "daemon_peak_rss_mb": peak,
        "daemon_rss_growth_mb": growth,
        "daemon_rss_samples": len(samples),
    }


def _status_kb(pid: int, key: str) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(key + ":"):
            return float(line.split()[1])
    return float("nan")
