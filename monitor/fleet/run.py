"""`monitor fleet run`: commission every machine and judge every log on a Dask cluster.

One task per machine trains its model (bytes of the .model.npz, shipped to the workers by
Dask); one task per log judges it.  The first training and the first judging run alone before
the rest: numba's on-disk cache races when several processes compile the same kernels at once
(numba#4807 with Dask workers, numba#10128), so one worker fills the cache and the others load
it.  Results come back to the client, which writes each one durably as it arrives.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from monitor.errors import MonitorError
from monitor.fleet import cluster, pipeline
from monitor.fleet.cluster import FleetInterrupted, RunOptions, Stop, flag_on_signals, wait
from monitor.fleet.commission import Models, models
from monitor.fleet.layout import Fleet, Machine, scan_fleet
from monitor.fleet.lock import results_lock
from monitor.fleet.outcome import Outcome
from monitor.fleet.progress import Progress
from monitor.fleet.pumpjob import PUMP, UNCOMMISSIONED, judge_pump_task
from monitor.fleet.store import Key, ResultStore, row_key
from monitor.io.digest import sha256_file

__all__ = ["FleetInterrupted", "ResultsWriteError", "RunOptions", "judge_task", "run_fleet"]


def judge_task(
    model_bytes: bytes,
    path: str,
    config: str | None,
    machine_id: str | None = None,
    loop: str | None = None,
) -> dict[str, Any]:
    """A worker's task: the row keys and events of one log (its loop ``loop``) of machine
    ``machine_id``, or why it could not be judged."""
    try:
        judged = pipeline.judge_log(model_bytes, path, config, machine_id, loop)
        return {"row": judged.row, "events": judged.events, "error": None}
    except (MonitorError, OSError, ValueError, KeyError) as exc:
        return {"row": {}, "events": [], "error": f"{type(exc).__name__}: {exc}"}


def _empty_row(
    machine: str, log: str, sha: str | None, model: str, error: str | None, loop: str | None = None
) -> dict:
    return {
        "machine": machine,
        "log": log,
        "sha256": sha,
        "verdict": "not_judged",
        "alarm": False,
        "fault": None,
        "sensor_fault": False,
        "max_j_ratio": None,
        "p95_j_ratio": None,
        "judged_s": 0.0,
        "first_alarm_t": None,
        "frames": None,
        "rejected": "{}",
        "model": model,
        "error": error,
        "max_j": None,
        "eps0": None,
        "samples": None,
        "max_level": None,
        "p50_j_ratio": None,
        "p50_j_drift": None,
        "loop": loop,
    }


#: A log to judge: its machine, path, SHA-256, and loop (None: the log as one loop).
Todo = list[tuple[Machine, Path, str, str | None]]


def _todo(
    fleet: Fleet, store: ResultStore, loops: tuple[str, ...] = ()
) -> tuple[Todo, list[dict], set[Key]]:
    """Logs (each of ``loops`` of them; none: the log as one loop) without a row yet, rows
    for what cannot be judged at all, and the (log, loop, sha256) key of every row this
    fleet has now (what the closing line counts)."""
    each: tuple[str | None, ...] = loops or (None,)
    done = store.done()
    todo, keys = [], set()
    bad = [_empty_row(r.machine, r.name, None, "-", f"refused: {r.reason}") for r in fleet.refused]
    for m in fleet.machines:
        if not m.logs and not any(
            r.name.startswith(f"{m.machine_id}/logs/") for r in fleet.refused
        ):
            why = "no logs (expected FLEET/<machine>/logs/*.log|*.csv)"
            bad.append(_empty_row(m.machine_id, f"{m.machine_id}/logs/", None, "-", why))
        for p in m.logs:
            log = fleet.relative(p)
            try:
                sha = sha256_file(p)
            except OSError as exc:
                bad.append(
                    _empty_row(m.machine_id, log, None, "-", f"unreadable: {exc.strerror or exc}")
                )
                continue
            for loop in each:
                key = row_key({"log": log, "sha256": sha, "loop": loop})
                keys.add(key)
                if key not in done:
                    todo.append((m, p, sha, loop))
    keys |= {row_key(r) for r in bad}
    return todo, bad, keys


def _submit(
    client: Any,
    fleet: Fleet,
    store: ResultStore,
    opts: RunOptions,
    todo: Todo,
    machine_models: Models,
    stop: Stop,
    progress: Progress,
) -> dict[Any, tuple[Machine, Path, str, str | None]]:
    """One judging task per log (loop), each future with what it judges.  A whole
    machine's loop without a model of its own (no commissioning data, or its training
    failed) is not judged: the config's model of the loop is another machine's, and its
    verdict would say healthy where the data cannot (its row: not judged, model default)."""
    futures: dict[Any, tuple[Machine, Path, str, str | None]] = {}
    for i, (m, p, sha, loop) in enumerate(todo):
        model, label = machine_models[(m.machine_id, loop)]
        if loop is not None and label.startswith("default"):
            row = _empty_row(m.machine_id, fleet.relative(p), sha, label, None, loop)
            if loop == PUMP:  # no commissioning data, or its commissioning failed
                failed = label.removeprefix("default (").removesuffix(")")
                row["not_judged_why"] = UNCOMMISSIONED if label == "default" else failed
            store.add(row, [])
            progress.judged(None)
            continue
        key = f"judge-{sha[:16]}-{i}"
        if loop == PUMP:  # the pump rule with the machine's own margin law
            fut = client.submit(judge_pump_task, model, str(p), opts.config, key=key, pure=False)
        else:
            fut = client.submit(
                judge_task, model, str(p), opts.config, m.machine_id, loop, key=key, pure=False
            )
        futures[fut] = (m, p, sha, loop)
        if len(futures) == 1:  # alone: it fills numba's cache for the detection kernels
            wait([fut], stop, progress)
    return futures


def _judge(
    client: Any,
    fleet: Fleet,
    store: ResultStore,
    opts: RunOptions,
    todo: Todo,
    stop: Stop,
    progress: Progress,
) -> None:
    """Commission the machines of ``todo`` and judge its logs, each row stored as it comes."""
    from distributed import as_completed

    needed = {(m.machine_id, loop) for m, _p, _sha, loop in todo}
    machine_models = models(client, fleet, store, opts, needed, stop, progress)
    progress.judging(len(todo))
    futures = _submit(client, fleet, store, opts, todo, machine_models, stop, progress)
    pending = as_completed(list(futures))
    while not pending.is_empty():
        stop.check()
        batch = pending.next_batch(block=False)
        if not batch:
            progress.refresh()
            time.sleep(0.1)
            continue
        for fut in batch:
            m, p, sha, loop = futures[fut]
            try:
                res = fut.result()
            except Exception as exc:  # noqa: BLE001 - a worker lost: the log's row says so
                res = {"row": {}, "events": [], "error": f"worker failed: {exc!r}"}
            label = machine_models[(m.machine_id, loop)][1]
            row = _empty_row(m.machine_id, fleet.relative(p), sha, label, res["error"], loop)
            row.update(res["row"])
            store.add(row, res["events"])
            progress.judged(row.get("frames"))


class ResultsWriteError(MonitorError, OSError):
    """RESULTS could not be written (a full disk, ...): the run stopped, finished logs kept."""

    exit_code = 3


def run_fleet(root: Path, out: Path, opts: RunOptions, progress: Progress) -> Outcome:
    """Judge every new log of FLEET into RESULTS; what the fleet's rows say.

    One run per RESULTS at a time (:func:`results_lock`).  The tables are written once, at
    the end: interrupted (:class:`FleetInterrupted`) or stopped by a full disk
    (:class:`ResultsWriteError`), they stay as they were before the run and the finished
    logs wait as parts, which the next run finds done and merges."""
    fleet = scan_fleet(root)
    try:
        with results_lock(out):
            return _run(fleet, ResultStore(out), opts, progress)
    except OSError as exc:
        if isinstance(exc, MonitorError):
            raise
        where = f" ({exc.filename})" if exc.filename else ""
        raise ResultsWriteError(
            f"{out}: cannot write the results: {exc.strerror or exc}"
            f"{where}; finished logs are kept, run again once it can "
            "be written"
        ) from None
    finally:
        progress.end()


def _run(fleet: Fleet, store: ResultStore, opts: RunOptions, progress: Progress) -> Outcome:
    stop = Stop()
    with flag_on_signals(stop):
        todo, bad, keys = _todo(fleet, store, opts.loops)
        for row in bad:
            store.add(row, [])
        n_logs = sum(len(m.logs) for m in fleet.machines)
        each = f" x {len(opts.loops)} loops ({', '.join(opts.loops)})" if opts.loops else ""
        if opts.loops:
            progress.per_loop()
        progress.say(
            f"fleet: {len(fleet.machines)} machines, {n_logs} logs{each}, {len(todo)} new"
            + (f", {len(fleet.refused)} refused" if fleet.refused else "")
        )
        try:
            stop.check()  # hashing a large fleet takes a while: a Ctrl-C starts no cluster
            if todo:
                with cluster.client(opts, progress.say) as client:
                    _judge(client, fleet, store, opts, todo, stop, progress)
                progress.close()
            stop.check()
        except FleetInterrupted:
            progress.close()
            finished = store.pending()
            raise FleetInterrupted(
                f"{finished} finished log(s) kept in {store.parts}, "
                f"the tables as before the run; run again to resume"
            ) from None
        store.compact()
    skipped = sum(1 for _log, _loop, sha in keys if sha) - len(todo)
    return Outcome.of(store.rows(), keys, new=len(todo), skipped=skipped, per_loop=bool(opts.loops))
