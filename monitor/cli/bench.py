"""``monitor bench``: GRNN, live tick, offline detect and memory, side by side in one run."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from monitor.cli._numbers import number
from monitor.cli._paths import output_dir, output_file
from monitor.errors import MonitorError

_DESCRIPTION = """\
Measure, in one run and on this machine: (1) GRNN query time of the detector's cut-off
kd-tree GRNN against a plain numba loop and pyGRNN for 2,000 / 20,000 / 200,000 patterns
(8 inputs, paper preset) and horizons p = 1, 10, 50, with the largest error relative to the
output's std, plotted as growth curves; (2) the live daemon on a python-can virtual bus
(20,000 patterns, p = 10): latency per tick from the arrival of the frame that completes a
row to the detector's result, p50/p99/max, CPU per tick, and state change to MON_Alarm
sent, and again with four loops in one daemon (boom, stick, bucket, swing: every row
ticked four times, latency to the last loop's result, CPU of the four ticks); (3) `monitor
detect` on a 1-hour log (p = 1, 20,000 patterns) in frames/s and times
real time, against python-can LogReader + cantools + pyGRNN on a 3-minute slice, per
frame; (4) the daemon's memory and `monitor detect`'s of a shipped log (peak RSS, wall),
kernels ahead of time and JIT side by side.  Medians throughout.  Writes JSON (--json), a
markdown table (stdout and --markdown) and a PNG (--plot).  Takes 20-30 minutes the first
time (the 1-hour log and the 20,000-pattern model are cached in --work-dir; the live part
replays 10 minutes in real time, the four-loop part 5 minutes); --quick runs
reduced sizes in about a minute (for CI: checks the pipeline, not the speed).
"""

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


def add_subparser(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "bench",
        help="benchmarks: GRNN, live tick latency, offline detect, memory",
        description=_DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--json",
        type=output_file,
        default=Path("bench.json"),
        metavar="F",
        help="result file (default bench.json)",
    )
    p.add_argument(
        "--markdown",
        type=output_file,
        default=None,
        metavar="F.md",
        help="markdown table (default: beside --json, .md)",
    )
    p.add_argument(
        "--plot",
        type=output_file,
        default=None,
        metavar="F.png",
        help="growth curves (default: beside --json, .png)",
    )
    p.add_argument(
        "--footprint-s",
        type=number(5.0, 86400.0, unit="s"),
        default=None,
        metavar="S",
        help="seconds of the daemon's RSS sampling, each of AOT and JIT (default 90, "
        "20 with --quick; 3600 for the hour-long soak that shows a leak as "
        "daemon_rss_growth_mb)",
    )
    p.add_argument(
        "--quick",
        action="store_true",
        help="reduced sizes (2,000 patterns, 90 s log): checks, not speed",
    )
    p.add_argument(
        "--work-dir",
        type=output_dir,
        default=None,
        metavar="DIR",
        help="cache for the long log and the models (default: a folder in the system's temp dir)",
    )
    p.add_argument(
        "--live-speed",
        type=float,
        default=None,
        metavar="X",
        help="replay speed of the live run (default 1: real time, 10 minutes; "
        "faster replays queue more ticks behind a stall)",
    )
    p.set_defaults(func=run)


def _say(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def _live(model: Path, seconds: float, speed: float, tmp: Path, loops: int) -> dict[str, Any]:
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


def run(args: argparse.Namespace) -> int:
    from monitor.bench import data, detect_bench, footprint, grnn_bench, report
    from monitor.model.modelfile import load_model

    sizes = data.QUICK if args.quick else data.FULL
    work = args.work_dir or Path(tempfile.gettempdir()) / "monitor-bench"
    try:
        work.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise MonitorError(f"cannot create --work-dir {work}: {exc.strerror or exc}") from None
    md_path = args.markdown or args.json.with_suffix(".md")
    png_path = args.plot or args.json.with_suffix(".png")
    for path in (args.json, md_path, png_path):
        if not path.parent.is_dir():
            raise MonitorError(f"cannot write {path}: folder {path.parent} does not exist")
    tmp = Path(tempfile.mkdtemp(prefix="monitor-bench-"))
    started = time.perf_counter()
    result: dict[str, Any] = {
        "quick": bool(args.quick),
        "machine": report.machine(),
        "load_before": report.load_average(),
    }

    _say("footprint: monitor --help, 5 processes")
    foot = footprint.cli_help()
    foot.update(footprint.daemon(args.footprint_s or (20.0 if args.quick else 90.0), _say))
    grnn = grnn_bench.measure(sizes, _say)
    model_path = data.monitor_model(work, sizes.headline_patterns, sizes.train_s, _say)
    summary = data.model_summary(load_model(model_path))
    _say(f"live: daemon on a virtual bus, {sizes.live_s:.0f} s of data, p = 10")
    speed = args.live_speed or sizes.live_speed
    live = _live(model_path, sizes.live_s, speed, tmp, 1)
    live["model_summary"] = summary
    _say(f"  tick p50 {live['tick_p50_ms']:.3f} ms, p99 {live['tick_p99_ms']:.3f} ms")
    four_s = min(sizes.live_s, 300.0)
    _say(f"live: four loops in one daemon, {four_s:.0f} s of data, p = 10")
    four = _live(model_path, four_s, speed, tmp, 4)
    four["model_summary"] = summary
    _say(f"  row p50 {four['tick_p50_ms']:.3f} ms, p99 {four['tick_p99_ms']:.3f} ms")
    log = data.long_log(work, sizes.log_s, sizes.fault_at_s, _say)
    det = detect_bench.measure(model_path, log, sizes.log_s, sizes.reference_s, _say)
    det["model_summary"] = summary

    result.update(
        {
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
    table = report.markdown(result)
    try:
        args.json.write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
        md_path.write_text(table, encoding="utf-8")
        grnn_bench.plot(grnn, png_path)
    except OSError as exc:
        raise MonitorError(f"cannot write output: {exc.strerror or exc} ({exc.filename})") from None
    print(table)
    _say(f"wrote {args.json}, {md_path}, {png_path} in {result['wall_s']:.0f} s")
    return 0
