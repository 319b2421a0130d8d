"""`monitor fleet run`: commission every machine and judge every log on a Dask cluster.

One task per machine trains its model (bytes of the .model.npz, shipped to the workers by
Dask); one task per log judges it.  The first training and the first judging run alone before
the rest: numba's on-disk cache races when several processes compile the same kernels at once
(numba#4807 with Dask workers, numba#10128), so one worker fills the cache and the others load
it.  Results come back to the client, which writes each one durably as it arrives.
"""

from __future__ import annotations

import hashlib
import logging
import os
import signal
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from types import FrameType
from typing import Any

from monitor.errors import MonitorError
from monitor.fleet import pipeline
from monitor.fleet.layout import Fleet, Machine, scan_fleet
from monitor.fleet.lock import results_lock
from monitor.fleet.outcome import Outcome
from monitor.fleet.progress import Progress
from monitor.fleet.store import ResultStore
from monitor.io.digest import sha256_file

Say = Callable[[str], None]

#: Dask's logging level in worker processes, read from the environment at their start.
_WORKER_LOG = "DASK_LOGGING__DISTRIBUTED"


@dataclass(frozen=True)
class RunOptions:
    workers: int = 2
    scheduler: str | None = None
    default_model: str | None = None
    config: str | None = None
    isolation: str = "sim"


def judge_task(model_bytes: bytes, path: str, config: str | None) -> dict[str, Any]:
    """A worker's task: the row keys and events of one log, or why it could not be judged."""
    try:
        judged = pipeline.judge_log(model_bytes, path, config)
        return {"row": judged.row, "events": judged.events, "error": None}
    except (MonitorError, OSError, ValueError, KeyError) as exc:
        return {"row": {}, "events": [], "error": f"{type(exc).__name__}: {exc}"}


def train_task(paths: list[str], config: str | None, isolation: str, reference: bytes) -> bytes:
    return pipeline.train_model_bytes(paths, config, isolation, reference)


def _empty_row(machine: str, log: str, sha: str | None, model: str, error: str) -> dict:
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
    }


class FleetInterrupted(KeyboardInterrupt):
    """Ctrl-C or SIGTERM during a run: the cluster is stopped, every finished log kept."""


class _Stop:
    """The flag SIGINT and SIGTERM set (a handler does nothing else); the run checks it
    between short waits, so it stops its cluster in order instead of dying inside Dask."""

    def __init__(self) -> None:
        self.signum: int | None = None

    def __call__(self, signum: int, _frame: FrameType | None) -> None:
        self.signum = signum

    def check(self) -> None:
        if self.signum is not None:
            raise FleetInterrupted(signal.Signals(self.signum).name)


@contextmanager
def _flag_on_signals(stop: _Stop) -> Iterator[None]:
    if threading.current_thread() is not threading.main_thread():
        yield  # a library caller's thread: no signals to take over
        return
    old = {s: signal.signal(s, stop) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)


@contextmanager
def _quiet_workers() -> Iterator[None]:
    """While local workers start.  They inherit an ignored SIGINT, so a Ctrl-C at the
    terminal (sent to the whole process group) reaches the client alone, which stops them;
    and Dask's own logging only for critical errors: a task's failure comes back to the
    client and into the log's row, while what workers log when stopped mid-task or when
    the scheduler closes before their last heartbeat is tracebacks the user cannot act on."""
    old_env = os.environ.get(_WORKER_LOG)
    os.environ[_WORKER_LOG] = "critical"
    main = threading.current_thread() is threading.main_thread()
    old = signal.signal(signal.SIGINT, signal.SIG_IGN) if main else None
    try:
        yield
    finally:
        if main:
            signal.signal(signal.SIGINT, old)
        if old_env is None:
            del os.environ[_WORKER_LOG]
        else:
            os.environ[_WORKER_LOG] = old_env


@contextmanager
def _client(opts: RunOptions, say: Say) -> Iterator[Any]:
    """A Dask client: on ``opts.scheduler``, or on a LocalCluster closed afterwards."""
    from distributed import Client, LocalCluster

    cluster = None
    if opts.scheduler:
        client = Client(opts.scheduler, timeout="30s")
        n = len(client.scheduler_info()["workers"])
        say(f"fleet: Dask scheduler {opts.scheduler}, {n} workers")
    else:
        with _quiet_workers():
            cluster = LocalCluster(
                n_workers=opts.workers,
                threads_per_worker=1,
                processes=True,
                dashboard_address="127.0.0.1:0",
            )
        client = Client(cluster)
        say(f"fleet: Dask LocalCluster, {opts.workers} workers")
    if client.dashboard_link:
        say(f"fleet: Dask dashboard {client.dashboard_link}")
    try:
        yield client
    finally:
        # What Dask logs while it stops (workers it kills, tasks it drops, mid-run after a
        # Ctrl-C) is not for the user: the run's own lines say what happened.
        for name in ("distributed", "tornado", "asyncio"):
            logging.getLogger(name).setLevel(logging.CRITICAL)
        client.close()
        if cluster is not None:
            cluster.close()


def _wait(futures: list[Any], stop: _Stop, progress: Progress) -> None:
    """Until every future is done, checking ``stop`` and redrawing the progress."""
    while not all(f.done() for f in futures):
        stop.check()
        progress.refresh()
        time.sleep(0.1)
    stop.check()


def _settings(default: bytes, opts: RunOptions) -> dict[str, Any]:
    """What every machine's model is trained with besides its own commissioning files (hashed
    once per run: the default model is megabytes)."""
    config = None if opts.config is None else sha256_file(Path(opts.config))
    return {
        "reference_sha256": hashlib.sha256(default).hexdigest(),
        "isolation": opts.isolation,
        "config_sha256": config,
        "train": pipeline.COMMISSIONING,
    }


def _manifest(m: Machine, fleet: Fleet, settings: dict[str, Any]) -> dict[str, Any]:
    """What a machine's model is trained from: a stored model trained from the same is
    reused, so a daily rerun commissions only new or changed machines."""
    return {
        "commissioning": {fleet.relative(p): sha256_file(p) for p in m.commissioning},
        **settings,
    }


def _models(
    client: Any,
    fleet: Fleet,
    store: ResultStore,
    opts: RunOptions,
    needed: set[str],
    stop: _Stop,
    progress: Progress,
) -> dict:
    """machine id -> (future or bytes of its model, model label), for the ``needed`` ones."""
    say = progress.say
    default = pipeline.default_model_bytes(opts.default_model, opts.config)
    out: dict[str, tuple[Any, str]] = {}
    manifests: dict[str, dict[str, Any]] = {}
    settings = _settings(default, opts)
    to_train: list[Machine] = []
    for m in fleet.machines:
        if m.machine_id not in needed:
            continue
        if not m.commissioning:
            say(f"fleet: {m.machine_id}: no commissioning data, judged with the default model")
            out[m.machine_id] = (default, "default")
            continue
        manifests[m.machine_id] = manifest = _manifest(m, fleet, settings)
        cached = store.cached_model(m.machine_id, manifest)
        if cached is not None:
            out[m.machine_id] = (cached, "commissioned")
        else:
            to_train.append(m)
    if to_train:
        progress.commissioning(len(to_train))
    for i, m in enumerate(to_train):
        # The default model floors the commissioned thresholds (minutes cannot show the
        # tail of hours: monitor.training.train.floor_thresholds).
        fut = client.submit(
            train_task,
            [str(p) for p in m.commissioning],
            opts.config,
            opts.isolation,
            default,
            key=f"train-{m.machine_id}",
            pure=False,
        )
        if i == 0:  # alone: it fills numba's cache for the training kernels
            _wait([fut], stop, progress)  # a failure is reported below, with the others'
        out[m.machine_id] = (fut, "training")
    reused = [mid for mid, (_, label) in out.items() if label == "commissioned"]
    if reused:
        say(f"fleet: {len(reused)} machine model(s) reused (commissioning unchanged)")
    for mid, (fut, label) in list(out.items()):
        if label != "training":
            continue
        _wait([fut], stop, progress)
        try:
            data = fut.result()
        except Exception as exc:  # noqa: BLE001 - any failure of a machine's training
            say(f"fleet: {mid}: commissioning failed ({exc}); judged with the default model")
            out[mid] = (default, f"default (commissioning failed: {exc})")
            continue
        store.save_model(mid, data, manifests[mid])
        out[mid] = (fut, "commissioned")
        progress.commissioned()
    for mid, (data, label) in out.items():
        if label.startswith("default"):
            store.save_model(mid, data, None)
    return out


Todo = list[tuple[Machine, Path, str]]


def _todo(fleet: Fleet, store: ResultStore) -> tuple[Todo, list[dict], set[tuple[str, str]]]:
    """Logs without a row yet, rows for what cannot be judged at all, and the (log, sha256)
    key of every row this fleet has now (what the closing line counts)."""
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
            keys.add((log, sha))
            if (log, sha) not in done:
                todo.append((m, p, sha))
    keys |= {(r["log"], "") for r in bad}
    return todo, bad, keys


def _judge(
    client: Any,
    fleet: Fleet,
    store: ResultStore,
    opts: RunOptions,
    todo: Todo,
    stop: _Stop,
    progress: Progress,
) -> None:
    """Commission the machines of ``todo`` and judge its logs, each row stored as it comes."""
    from distributed import as_completed

    needed = {m.machine_id for m, _p, _sha in todo}
    models = _models(client, fleet, store, opts, needed, stop, progress)
    futures: dict[Any, tuple[Machine, Path, str]] = {}
    progress.judging(len(todo))
    for i, (m, p, sha) in enumerate(todo):
        fut = client.submit(
            judge_task,
            models[m.machine_id][0],
            str(p),
            opts.config,
            key=f"judge-{sha[:16]}-{i}",
            pure=False,
        )
        futures[fut] = (m, p, sha)
        if i == 0:  # alone: it fills numba's cache for the detection kernels
            _wait([fut], stop, progress)
    pending = as_completed(list(futures))
    while not pending.is_empty():
        stop.check()
        batch = pending.next_batch(block=False)
        if not batch:
            progress.refresh()
            time.sleep(0.1)
            continue
        for fut in batch:
            m, p, sha = futures[fut]
            try:
                res = fut.result()
            except Exception as exc:  # noqa: BLE001 - a worker lost: the log's row says so
                res = {"row": {}, "events": [], "error": f"worker failed: {exc!r}"}
            label = models[m.machine_id][1]
            row = _empty_row(m.machine_id, fleet.relative(p), sha, label, res["error"])
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
    stop = _Stop()
    with _flag_on_signals(stop):
        todo, bad, keys = _todo(fleet, store)
        for row in bad:
            store.add(row, [])
        n_logs = sum(len(m.logs) for m in fleet.machines)
        progress.say(
            f"fleet: {len(fleet.machines)} machines, {n_logs} logs, {len(todo)} new"
            + (f", {len(fleet.refused)} refused" if fleet.refused else "")
        )
        try:
            stop.check()  # hashing a large fleet takes a while: a Ctrl-C starts no cluster
            if todo:
                with _client(opts, progress.say) as client:
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
    skipped = sum(1 for _log, sha in keys if sha) - len(todo)
    return Outcome.of(store.rows(), keys, new=len(todo), skipped=skipped)
