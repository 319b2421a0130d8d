"""``monitor bench``'s measurements in one run: the footprint, the GRNN, the live daemon
(one loop and four), `monitor detect` against the reference pipeline, each against its goal."""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from monitor.bench import data, detect_bench, footprint, grnn_bench, report
from monitor.errors import MonitorError

Progress = Callable[[str], None]

GOALS = {
    "grnn_us_per_query": ("<= 10 us at 20,000 patterns", lambda v: v <= 10.0),
    "grnn_speedup_vs_numba_loop": (">= 36x", lambda v: v >= 36.0),
    "grnn_max_rel_error": ("<= 1e-6", lambda v: v <= 1e-6),
    "tick_p99_ms": ("< 1 ms at 20,000 patterns, p = 10", lambda v: v < 1.0),
    # Four loops keep up when a row's four ticks end within one 100 Hz sample period.
    "four_loop_tick_p99_ms": ("< 10 ms (one sample period), four loops", lambda v: v < 10.0),
    "detect_realtime_factor": (">= 1000x", lambda v: v >= 1000.0),
    "cli_help_s": ("<= 0.5 s", lambda v: v <= 0.5),
    "cli_help_rss_mb": ("<= 60 MB", lambda v: v <= 60.0),
    "daemon_rss_mb": ("<= 150 MB steady, daemon process alone", lambda v: v <= 150.0),
    "daemon_start_s": ("<= 3 s to the first tick, warm cache", lambda v: v <= 3.0),
    "detect_rss_mb": ("<= 150 MB, `monitor detect` of a shipped 90 s log", lambda v: v <= 150.0),
}


def measure_all(
    sizes: data.Sizes,
    work: Path,
    footprint_s: float,
    live_speed: float,
    say: Progress,
    numba_cache: Path | None = None,
) -> dict[str, Any]:
    """Every measurement at ``sizes`` (the long log and the models cached in ``work``),
    the headline figures on top and each goal met or not; the warm figures with
    ``numba_cache`` when given (a cache `monitor warm-up` filled), else a new warm one."""
    from monitor.model.modelfile import load_model

    tmp = Path(tempfile.mkdtemp(prefix="monitor-bench-"))
    started = time.perf_counter()
    result: dict[str, Any] = {
        "quick": sizes is data.QUICK,
        "machine": report.machine(),
        "load_before": report.load_average(),
    }
    say("footprint: monitor --help, 5 processes")
    foot = footprint.cli_help()
    foot.update(footprint.daemon(footprint_s, say, warm_cache=numba_cache))
    grnn = grnn_bench.measure(sizes, say)
    model_path = data.monitor_model(work, sizes.headline_patterns, sizes.train_s, say)
    summary = data.model_summary(load_model(model_path))
    say(f"live: daemon on a virtual bus, {sizes.live_s:.0f} s of data, p = 10")
    live = _live(model_path, sizes.live_s, live_speed, tmp, 1)
    live["model_summary"] = summary
    say(f"  tick p50 {live['tick_p50_ms']:.3f} ms, p99 {live['tick_p99_ms']:.3f} ms")
    four_s = min(sizes.live_s, 300.0)
    say(f"live: four loops in one daemon, {four_s:.0f} s of data, p = 10")
    four = _live(model_path, four_s, live_speed, tmp, 4)
    four["model_summary"] = summary
    say(f"  row p50 {four['tick_p50_ms']:.3f} ms, p99 {four['tick_p99_ms']:.3f} ms")
    log = data.long_log(work, sizes.log_s, sizes.fault_at_s, say)
    det = detect_bench.measure(model_path, log, sizes.log_s, sizes.reference_s, say)
    det["model_summary"] = summary
    result.update(_headline(grnn, live, foot, four, det))
    result.update(
        {
            "grnn": grnn,
            "live": live,
            "four_loop": four,
            "detect": det,
            "load_after": report.load_average(),
            "wall_s": time.perf_counter() - started,
        }
    )
    result["goals"] = {
        k: {"text": text, "met": result[k] is not None and bool(ok(result[k]))}
        for k, (text, ok) in GOALS.items()
    }
    return result


def _headline(
    grnn: dict[str, Any],
    live: dict[str, Any],
    foot: dict[str, Any],
    four: dict[str, Any],
    det: dict[str, Any],
) -> dict[str, Any]:
    """The figures the goals and the table's top rows name, from their parts."""
    return {
        "grnn_us_per_query": grnn["grnn_us_per_query"],
        "grnn_speedup_vs_numba_loop": grnn["grnn_speedup_vs_numba_loop"],
        "grnn_speedup_vs_pygrnn": grnn["grnn_speedup_vs_pygrnn"],
        "grnn_max_rel_error": grnn["grnn_max_rel_error"],
        "tick_p50_ms": live["tick_p50_ms"],
        "tick_p99_ms": live["tick_p99_ms"],
        "tick_max_ms": live["tick_max_ms"],
        "live_bench_peak_rss_mb": live["peak_rss_mb"],  # with the bench's own simulation
        **foot,
        "four_loop_tick_p50_ms": four["tick_p50_ms"],
        "four_loop_tick_p99_ms": four["tick_p99_ms"],
        "four_loop_tick_cpu_median_ms": four["tick_cpu_median_ms"],
        "four_loop_tick_cpu_p99_ms": four["tick_cpu_p99_ms"],
        "four_loop_peak_rss_mb": four["peak_rss_mb"],
        "detect_frames_per_s": det["detect_frames_per_s"],
        "detect_realtime_factor": det["detect_realtime_factor"],
        "detect_speedup_vs_reference_pipeline": det["detect_speedup_vs_reference_pipeline"],
    }


def _live(model: Path, seconds: float, speed: float, tmp: Path, loops: int) -> dict[str, Any]:
    """``monitor.bench.live`` in a process of its own (the daemon alone in it): its JSON."""
    out = tmp / f"live{loops}.json"
    cmd = [
        sys.executable,
        "-m",
        "monitor.bench.live",
        "--model",
        str(model),
        "--horizon",
        "10",
        "--seconds",
        str(seconds),
        "--speed",
        str(speed),
        "--json",
        str(out),
        "--loops",
        str(loops),
    ]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        tail = proc.stderr.strip().splitlines()[-1:] or ["(no output)"]
        raise MonitorError(f"the live benchmark failed: {tail[0]}")
    return json.loads(out.read_text())
