"""`monitor fleet bench`: logs/s and frames/s of judging a fleet's logs in one process (the
`monitor detect` loop) and on a Dask LocalCluster of 1 and 2 workers, side by side.

Models come from a finished run's RESULTS/models, so only judging is timed; every timing
starts after a warm-up (numba's cache filled, workers started)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from monitor.fleet import pipeline
from monitor.fleet.layout import scan_fleet
from monitor.fleet.run import judge_task


def _jobs(fleet_root: Path, results: Path) -> list[tuple[bytes, str]]:
    fleet = scan_fleet(fleet_root)
    jobs = []
    for m in fleet.machines:
        model = results / "models" / f"{m.machine_id}.model.npz"
        if model.is_file():
            jobs += [(model.read_bytes(), str(p)) for p in m.logs]
    return jobs


def bench_fleet(fleet_root: Path, results: Path, workers: tuple[int, ...] = (1, 2)) -> dict:
    from distributed import Client, LocalCluster

    jobs = _jobs(fleet_root, results)
    pipeline.judge_log(*jobs[0])  # warm-up: numba's cache
    start = time.perf_counter()
    frames = sum(pipeline.judge_log(m, p).row["frames"] or 0 for m, p in jobs)
    out: dict[str, Any] = {"logs": len(jobs), "frames": frames}
    out["one_process_s"] = time.perf_counter() - start
    for n in workers:
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, dashboard_address=None)
        with cluster, Client(cluster) as client:
            models = {m: client.scatter(m, broadcast=True) for m in {m for m, _ in jobs}}
            client.run(pipeline.judge_log, *jobs[0])  # every worker warm
            start = time.perf_counter()
            futs = [client.submit(judge_task, models[m], p, None, pure=False) for m, p in jobs]
            client.gather(futs)
            out[f"workers_{n}_s"] = time.perf_counter() - start
    for key in [k for k in out if k.endswith("_s")]:
        name = key[:-2]
        out[f"{name}_logs_per_s"] = len(jobs) / out[key]
        out[f"{name}_frames_per_s"] = frames / out[key]
    return out
