"""`monitor fleet bench`: frames/s of judging a fleet's logs with `monitor detect`'s code path,
in one process as the fleet's task, and on Dask LocalClusters of 1 and 2 workers, side by side.

Models come from a finished run's RESULTS/models, so only judging is timed; every timing
starts after a warm-up (numba's cache filled, workers started).  The ways are timed in turn
within each repeat, so a change of the machine's load touches them all alike, and each
reports the median of its repeats: on a shared machine the ratios to `monitor detect` per
worker mean more than the rates."""

from __future__ import annotations

import contextlib
import os
import resource
import statistics
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from monitor.errors import ConfigError
from monitor.fleet import pipeline
from monitor.fleet.cluster import local_cluster
from monitor.fleet.layout import scan_fleet
from monitor.fleet.run import judge_task

#: The baseline every way is compared with: `monitor detect` over each log in turn.
DETECT = "detect"


def _jobs(fleet_root: Path, results: Path) -> list[tuple[bytes, str]]:
    fleet = scan_fleet(fleet_root)
    jobs = []
    for m in fleet.machines:
        model = results / "models" / f"{m.machine_id}.model.npz"
        if model.is_file():
            jobs += [(model.read_bytes(), str(p)) for p in m.logs]
    return jobs


#: A way of judging every log once: returns the CPU seconds it took (all its processes).
Once = Callable[[], float]


def _in_process(jobs: list[tuple[bytes, str]], judge: Callable[[bytes, str], Any]) -> Once:
    def once() -> float:
        cpu = time.process_time()
        for m, p in jobs:
            judge(m, p)
        return time.process_time() - cpu

    return once


def _cpu_s(client: Any) -> float:
    """CPU seconds of every worker process so far (its heartbeats and task handling too)."""
    return sum(client.run(time.process_time).values())


def _peak_rss_mb() -> float:
    """This process's peak resident memory so far, MB (Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _rss_mb() -> float:
    """This process's resident memory now, MB (what a worker keeps between logs)."""
    resident_pages = int(Path("/proc/self/statm").read_text().split()[1])  # Linux
    return resident_pages * resource.getpagesize() / 2**20


@contextlib.contextmanager
def _on_dask(
    jobs: list[tuple[bytes, str]], n: int, dask_default: bool
) -> Iterator[tuple[Once, Callable[[], Iterator[float]]]]:
    """`monitor fleet run`'s LocalCluster of ``n`` single-threaded workers (with Dask's
    default worker environment if ``dask_default``), warm, and a function judging every log
    on it as the run does (the model scattered once, one task a log), and one giving the
    largest peak RSS and the largest RSS now of its workers (MB)."""
    from distributed import Client

    local = local_cluster(n, dashboard_address=None, dask_default=dask_default)
    with local as cluster, Client(cluster) as client:
        models = {m: client.scatter(m, broadcast=True) for m in {m for m, _ in jobs}}
        client.run(pipeline.judge_log, *jobs[0])  # every worker warm

        def once() -> float:
            cpu = _cpu_s(client)
            futs = [client.submit(judge_task, models[m], p, None, pure=False) for m, p in jobs]
            client.gather(futs)
            return _cpu_s(client) - cpu

        yield once, lambda: (max(client.run(f).values()) for f in (_peak_rss_mb, _rss_mb))


def _rates(seconds: list[float], cpu_s: list[float], frames: int, workers: int) -> dict:
    median_s = statistics.median(seconds)
    median_cpu_s = statistics.median(cpu_s)
    return {
        "workers": workers,
        "s": seconds,
        "median_s": median_s,
        "frames_per_s": frames / median_s,
        "frames_per_s_per_worker": frames / median_s / workers,
        "cpu_s": cpu_s,
        "median_cpu_s": median_cpu_s,
        "frames_per_cpu_s": frames / median_cpu_s,
    }


def bench_fleet(
    fleet_root: Path,
    results: Path,
    workers: tuple[int, ...] = (1, 2),
    repeats: int = 3,
    dask_default: bool = False,
) -> dict[str, Any]:
    """Seconds, frames/s and frames/s per worker of judging every log of the fleet: with
    `monitor detect`'s code (``detect``), as the fleet's task in one process
    (``one_process``) and on Dask (``workers_N``; with ``dask_default`` also
    ``workers_N_dask_default``, workers in Dask's own default environment); each one's
    per-worker rate over detect's (``vs_detect_per_worker``), from the medians of
    ``repeats`` timings; and frames per CPU second of all its processes
    (``frames_per_cpu_s``: what a cluster's cores cost, whatever else the machine runs)."""
    jobs = _jobs(fleet_root, results)
    if not jobs:
        raise ConfigError(f"{results / 'models'}: no model for any machine of {fleet_root}")
    frames = sum(pipeline.detect_frames(m, p) for m, p in jobs)  # and numba's cache warm
    pipeline.judge_log(*jobs[0])
    load_start = os.getloadavg()
    ways: dict[str, tuple[int, Once]] = {
        DETECT: (1, _in_process(jobs, pipeline.detect_frames)),
        "one_process": (1, _in_process(jobs, pipeline.judge_log)),
    }
    peaks: dict[str, Callable[[], Iterator[float]]] = {}
    seconds: dict[str, list[float]] = {name: [] for name in ways}
    cpu_s: dict[str, list[float]] = {name: [] for name in ways}
    with contextlib.ExitStack() as stack:
        for n, default in [(n, d) for n in workers for d in (False, True)[: 1 + dask_default]]:
            name = f"workers_{n}" + ("_dask_default" if default else "")
            once, peaks[name] = stack.enter_context(_on_dask(jobs, n, default))
            ways[name] = (n, once)
            seconds[name] = []
            cpu_s[name] = []
        for _ in range(repeats):
            for name, (_n, once) in ways.items():
                start = time.perf_counter()
                cpu_s[name].append(once())
                seconds[name].append(time.perf_counter() - start)
        worker_rss = {name: tuple(peak()) for name, peak in peaks.items()}
    runs = {name: _rates(seconds[name], cpu_s[name], frames, n) for name, (n, _) in ways.items()}
    base, base_cpu = runs[DETECT]["frames_per_s_per_worker"], runs[DETECT]["frames_per_cpu_s"]
    for name, r in runs.items():
        r["vs_detect_per_worker"] = r["frames_per_s_per_worker"] / base
        r["cpu_vs_detect"] = r["frames_per_cpu_s"] / base_cpu
        r["worker_peak_rss_mb"], r["worker_rss_after_mb"] = worker_rss.get(name, (None, None))
    return {
        "logs": len(jobs),
        "frames": frames,
        "repeats": repeats,
        "load_average": {"start": load_start, "end": os.getloadavg()},
        # detect's and the one-process task's judging, and the bench's own imports
        "process_peak_rss_mb": _peak_rss_mb(),
        "runs": runs,
    }


def table(out: dict[str, Any]) -> str:
    """The result as the Markdown table of docs/benchmarks.md."""
    lines = [
        "| how | workers | median s | frames/s | frames/s per worker | per worker vs detect "
        "| median CPU s | frames per CPU-s | vs detect | worker peak RSS MB | RSS after MB |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, r in out["runs"].items():
        peak, after = r["worker_peak_rss_mb"], r["worker_rss_after_mb"]
        lines.append(
            f"| {name} | {r['workers']} | {r['median_s']:.2f} | {r['frames_per_s']:,.0f} "
            f"| {r['frames_per_s_per_worker']:,.0f} | {r['vs_detect_per_worker']:.2f} "
            f"| {r['median_cpu_s']:.2f} | {r['frames_per_cpu_s']:,.0f} "
            f"| {r['cpu_vs_detect']:.2f} | {'-' if peak is None else f'{peak:,.0f}'} "
            f"| {'-' if after is None else f'{after:,.0f}'} |"
        )
    peak = out["process_peak_rss_mb"]
    lines.append(f"\nbench process peak RSS (detect, one process): {peak:,.0f} MB")
    return "\n".join(lines)
