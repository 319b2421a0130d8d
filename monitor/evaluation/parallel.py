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
from collections.abc import Callable, Sequence
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


def score_batch(specs: list[RunSpec], paths: tuple[str, ...], cfg: EvalConfig) -> list[Any]:
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
    from monitor.model.modelfile import save_model

    say = progress or (lambda _msg: None)
    plan = normal_plan(cfg) + fault_plan(cfg)
    eta = Eta(plan, say)
    with tempfile.TemporaryDirectory(prefix="eval-sim-") as tmp:
        paths = []
        for k, m in enumerate(models):
            path = Path(tmp) / f"model{k}.npz"
            save_model(path, m.model)
            paths.append(str(path))
        scored = map_batches(plan, score_batch, (tuple(paths), cfg), workers, eta)
    sim_s = 0.0
    for spec, (rows, s, det_s) in zip(plan, scored, strict=True):
        sim_s += s
        collect(models, spec, rows, det_s)
    return {"simulate_s": sim_s, "runs_s": time.perf_counter() - eta.started}


def map_batches(
    plan: Sequence[RunSpec],
    task: Callable[..., list[Any]],
    task_args: tuple[Any, ...],
    workers: int,
    eta: Eta,
) -> list[Any]:
    """``task(batch, *task_args)`` (one result per run of the batch) over ``plan`` in
    batches of ``BATCH_RUNS`` on a Dask ``LocalCluster`` of ``workers`` processes: the
    results in plan order, ``eta`` told of every run done."""
    from distributed import Client, LocalCluster, as_completed

    batches = [list(plan[i : i + BATCH_RUNS]) for i in range(0, len(plan), BATCH_RUNS)]
    results: list[Any] = [None] * len(batches)
    cluster = LocalCluster(
        n_workers=workers, threads_per_worker=1, processes=True, dashboard_address="127.0.0.1:0"
    )
    with cluster, Client(cluster) as client:
        eta.say(f"Dask LocalCluster, {workers} workers, dashboard {client.dashboard_link}")
        first = client.submit(task, batches[0], *task_args, pure=False)
        results[0] = first.result()
        for spec in batches[0]:
            eta.step(spec)
        futures = {
            client.submit(task, b, *task_args, pure=False): k for k, b in enumerate(batches[1:], 1)
        }
        for fut in as_completed(futures):
            k = futures[fut]
            results[k] = fut.result()
            for spec in batches[k]:
                eta.step(spec)
    return [r for scored in results for r in scored]


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
