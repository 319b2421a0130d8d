"""``monitor eval-sim --workers N``: the planned runs on a Dask ``LocalCluster``.

Each task simulates a small batch of runs and scores them with every model, exactly as the
one-process loop does (``sim_eval.score_spec``), so the rows are the same.  The models go to
the workers as model files (written once to a temporary folder) and are loaded once per
worker process.  The first task runs alone: it fills numba's on-disk cache, which races when
several processes compile the same kernels at once (numba#4807, numba#10128).
"""

from __future__ import annotations

import functools
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from monitor.evaluation.sim_eval import (
    Eta,
    EvalConfig,
    ModelUnderTest,
    Progress,
    RunSpec,
    collect,
    fault_plan,
    normal_plan,
    run_all,
    score_spec,
)

#: Runs per task: a few seconds of work each, so the scheduler's overhead stays small.
BATCH_RUNS = 6


@functools.cache
def _load(path: str) -> ModelUnderTest:
    from monitor.model.modelfile import load_model

    return ModelUnderTest(Path(path).stem, load_model(path), path)


def score_batch(paths: tuple[str, ...], specs: list[RunSpec], cfg: EvalConfig) -> list[Any]:
    """A worker's task: every run of ``specs`` scored by the models at ``paths``."""
    models = [_load(p) for p in paths]
    return [score_spec(models, spec, cfg) for spec in specs]


def run_parallel(
    models: Sequence[ModelUnderTest],
    cfg: EvalConfig,
    workers: int,
    progress: Progress | None = None,
) -> dict[str, float]:
    """``sim_eval.run_all`` on ``workers`` Dask worker processes; the same rows, in plan order."""
    from distributed import Client, LocalCluster, as_completed

    from monitor.model.modelfile import save_model

    say = progress or (lambda _msg: None)
    plan = normal_plan(cfg) + fault_plan(cfg)
    batches = [plan[i : i + BATCH_RUNS] for i in range(0, len(plan), BATCH_RUNS)]
    results: list[Any] = [None] * len(batches)
    sim_s = 0.0
    eta = Eta(plan, say)
    with tempfile.TemporaryDirectory(prefix="eval-sim-") as tmp:
        paths = []
        for k, m in enumerate(models):
            path = Path(tmp) / f"model{k}.npz"
            save_model(path, m.model)
            paths.append(str(path))
        cluster = LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True, dashboard_address="127.0.0.1:0"
        )
        with cluster, Client(cluster) as client:
            say(f"Dask LocalCluster, {workers} workers, dashboard {client.dashboard_link}")
            first = client.submit(score_batch, tuple(paths), batches[0], cfg, pure=False)
            results[0] = first.result()
            for spec in batches[0]:
                eta.step(spec)
            futures = {
                client.submit(score_batch, tuple(paths), b, cfg, pure=False): k
                for k, b in enumerate(batches[1:], 1)
            }
            for fut in as_completed(futures):
                k = futures[fut]
                results[k] = fut.result()
                for spec in batches[k]:
                    eta.step(spec)
    for batch, scored in zip(batches, results, strict=True):
        for spec, (rows, s, det_s) in zip(batch, scored, strict=True):
            sim_s += s
            collect(models, spec, rows, det_s)
    return {"simulate_s": sim_s, "runs_s": time.perf_counter() - eta.started}


def score_all(
    models: Sequence[ModelUnderTest],
    cfg: EvalConfig,
    workers: int,
    progress: Progress | None = None,
) -> dict[str, float]:
    """Every planned run scored by every model, in this process (``workers`` 1) or on
    ``workers`` Dask worker processes: the same rows either way; returns timings (s)."""
    say = progress or (lambda _msg: None)
    say(
        f"scoring {len(fault_plan(cfg))} fault run(s) and {len(normal_plan(cfg))} normal run(s) "
        f"with {len(models)} model(s): {', '.join(m.label for m in models)}"
    )
    if workers > 1:
        return run_parallel(models, cfg, workers, say)
    return run_all(models, cfg, say)
