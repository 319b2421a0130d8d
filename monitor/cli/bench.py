"""``monitor bench``: GRNN, live tick, offline detect and memory, side by side in one run."""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

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
        "--numba-cache",
        type=_warm_cache,
        default=None,
        metavar="DIR",
        help="measure the warm start, `monitor detect` and the memory with this numba cache, "
        "already filled by `monitor warm-up` (e.g. the unit's /var/cache/hydraulic-monitor), "
        "instead of warming up a new one (warm_up_s is then not measured)",
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


def _warm_cache(text: str) -> Path:
    """A numba cache folder that `monitor warm-up` filled (its index files are there)."""
    p = Path(text)
    if not p.is_dir():
        raise argparse.ArgumentTypeError(f"{p} is not a folder")
    if not any(p.rglob("*.nbi")):
        raise argparse.ArgumentTypeError(
            f"{p} holds no numba cache: fill it first with NUMBA_CACHE_DIR={p} monitor warm-up"
        )
    return p


def _say(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def run(args: argparse.Namespace) -> int:
    from monitor.bench import data, grnn_bench, report, suite

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
    footprint_s = args.footprint_s or (20.0 if args.quick else 90.0)
    result = suite.measure_all(
        sizes, work, footprint_s, args.live_speed or sizes.live_speed, _say, args.numba_cache
    )
    table = report.markdown(result)
    try:
        args.json.write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
        md_path.write_text(table, encoding="utf-8")
        grnn_bench.plot(result["grnn"], png_path)
    except OSError as exc:
        raise MonitorError(f"cannot write output: {exc.strerror or exc} ({exc.filename})") from None
    print(table)
    _say(f"wrote {args.json}, {md_path}, {png_path} in {result['wall_s']:.0f} s")
    return 0
