"""`monitor fleet run`: commission every machine and judge every log on a Dask cluster.

One task per machine trains its model (bytes of the .model.npz, shipped to the workers by
Dask); one task per log judges it.  The first training and the first judging run alone before
the rest: numba's on-disk cache races when several processes compile the same kernels at once
(numba#4807 with Dask workers, numba#10128), so one worker fills the cache and the others load
it.  Results come back to the client, which writes each one durably as it arrives.
"""

from __future__ import annotations

import hashlib
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from monitor.errors import MonitorError
from monitor.fleet import pipeline
from monitor.fleet.layout import Fleet, Machine, scan_fleet
from monitor.fleet.store import ResultStore
from monitor.io.digest import sha256_file

Say = Callable[[str], None]


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
    return {"machine": machine, "log": log, "sha256": sha, "verdict": "not_judged",
            "alarm": False, "fault": None, "sensor_fault": False, "max_j_ratio": None,
            "p95_j_ratio": None, "judged_s": 0.0, "first_alarm_t": None, "frames": None,
            "rejected": "{}", "model": model, "error": error, "max_j": None, "eps0": None,
            "samples": None, "max_level": None, "p50_j_ratio": None,
            "p50_j_drift": None}  # fmt: skip


class _Progress:
    def __init__(self, total: int, say: Say) -> None:
        self.total, self.say, self.done, self.frames = total, say, 0, 0
        self.start = self.last = time.monotonic()

    def tick(self, frames: int | None, force: bool = False) -> None:
        self.done += 1
        self.frames += frames or 0
        now = time.monotonic()
        if not force and now - self.last < 2.0 and self.done < self.total:
            return
        self.last = now
        elapsed = max(now - self.start, 1e-9)
        eta = (self.total - self.done) * elapsed / self.done
        self.say(f"fleet: {self.done}/{self.total} logs, {self.frames / elapsed:,.0f} frames/s, "
                 f"ETA {eta:.0f} s")  # fmt: skip


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
        cluster = LocalCluster(n_workers=opts.workers, threads_per_worker=1, processes=True,
                               dashboard_address="127.0.0.1:0")  # fmt: skip
        client = Client(cluster)
        say(f"fleet: Dask LocalCluster, {opts.workers} workers")
    if client.dashboard_link:
        say(f"fleet: Dask dashboard {client.dashboard_link}")
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _settings(default: bytes, opts: RunOptions) -> dict[str, Any]:
    """What every machine's model is trained with besides its own commissioning files (hashed
    once per run: the default model is megabytes)."""
    config = None if opts.config is None else sha256_file(Path(opts.config))
    return {"reference_sha256": hashlib.sha256(default).hexdigest(),
            "isolation": opts.isolation, "config_sha256": config,
            "train": pipeline.COMMISSIONING}  # fmt: skip


def _manifest(m: Machine, fleet: Fleet, settings: dict[str, Any]) -> dict[str, Any]:
    """What a machine's model is trained from: a stored model trained from the same is
    reused, so a daily rerun commissions only new or changed machines."""
    return {"commissioning": {fleet.relative(p): sha256_file(p) for p in m.commissioning},
            **settings}  # fmt: skip


def _models(client: Any, fleet: Fleet, store: ResultStore, opts: RunOptions, needed: set[str],
            say: Say) -> dict:  # fmt: skip
    """machine id -> (future or bytes of its model, model label), for the ``needed`` ones."""
    from distributed import wait

    default = pipeline.default_model_bytes(opts.default_model, opts.config)
    out: dict[str, tuple[Any, str]] = {}
    manifests: dict[str, dict[str, Any]] = {}
    settings = _settings(default, opts)
    first = True
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
            continue
        # The default model floors the commissioned thresholds (minutes cannot show the
        # tail of hours: monitor.training.train.floor_thresholds).
        fut = client.submit(train_task, [str(p) for p in m.commissioning], opts.config,
                            opts.isolation, default, key=f"train-{m.machine_id}",
                            pure=False)  # fmt: skip
        if first:  # alone: it fills numba's cache for the training kernels
            wait([fut])  # a failure is reported below, with the others'
            first = False
        out[m.machine_id] = (fut, "training")
    reused = [mid for mid, (_, label) in out.items() if label == "commissioned"]
    if reused:
        say(f"fleet: {len(reused)} machine model(s) reused (commissioning unchanged)")
    for mid, (fut, label) in list(out.items()):
        if label != "training":
            continue
        try:
            data = fut.result()
        except Exception as exc:  # noqa: BLE001 - any failure of a machine's training
            say(f"fleet: {mid}: commissioning failed ({exc}); judged with the default model")
            out[mid] = (default, f"default (commissioning failed: {exc})")
            continue
        store.save_model(mid, data, manifests[mid])
        out[mid] = (fut, "commissioned")
    for mid, (data, label) in out.items():
        if label.startswith("default"):
            store.save_model(mid, data, None)
    return out


def _todo(fleet: Fleet, store: ResultStore) -> tuple[list[tuple[Machine, Path, str]], list]:
    """Logs without a row yet, and rows for what cannot be judged at all."""
    done = store.done()
    todo, bad = [], []
    for m in fleet.machines:
        if not m.logs:
            bad.append(
                _empty_row(
                    m.machine_id,
                    f"{m.machine_id}/logs/",
                    None,
                    "-",
                    "no logs (expected FLEET/<machine>/logs/*.log|*.csv)",
                )
            )
        for p in m.logs:
            log = fleet.relative(p)
            try:
                sha = sha256_file(p)
            except OSError as exc:
                bad.append(
                    _empty_row(m.machine_id, log, None, "-", f"unreadable: {exc.strerror or exc}")
                )
                continue
            if (log, sha) not in done:
                todo.append((m, p, sha))
    return todo, bad


def run_fleet(root: Path, out: Path, opts: RunOptions, say: Say) -> dict[str, int]:
    """Judge every new log of FLEET into RESULTS; counts of logs judged, skipped and rows."""
    from distributed import as_completed

    fleet = scan_fleet(root)
    store = ResultStore(out)
    store.compact()  # parts of a killed run first
    todo, bad = _todo(fleet, store)
    for row in bad:
        store.add(row, [])
    n_logs = sum(len(m.logs) for m in fleet.machines)
    say(f"fleet: {len(fleet.machines)} machines, {n_logs} logs, {len(todo)} new")
    if todo:
        with _client(opts, say) as client:
            needed = {m.machine_id for m, _p, _sha in todo}
            models = _models(client, fleet, store, opts, needed, say)
            futures: dict[Any, tuple[Machine, Path, str]] = {}
            for i, (m, p, sha) in enumerate(todo):
                fut = client.submit(judge_task, models[m.machine_id][0], str(p), opts.config,
                                    key=f"judge-{sha[:16]}-{i}", pure=False)  # fmt: skip
                futures[fut] = (m, p, sha)
                if i == 0:  # alone: it fills numba's cache for the detection kernels
                    fut.result()
            progress = _Progress(len(todo), say)
            for fut in as_completed(list(futures)):
                m, p, sha = futures[fut]
                res = fut.result()
                label = models[m.machine_id][1]
                row = _empty_row(m.machine_id, fleet.relative(p), sha, label, res["error"])
                row.update(res["row"])
                store.add(row, res["events"])
                progress.tick(row.get("frames"))
    rows = store.compact()
    return {"judged": len(todo), "skipped": n_logs - len(todo), "rows": rows}
