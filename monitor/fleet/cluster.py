"""The Dask side of `monitor fleet run`: the client (on a scheduler, or a LocalCluster it
closes), and the flag Ctrl-C and SIGTERM set so a run stops its cluster in order."""

from __future__ import annotations

import logging
import os
import signal
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from types import FrameType
from typing import Any

from monitor.fleet.progress import Progress

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
    #: Each log judged per loop of the config's ``loops:`` (whole machines); () as one loop.
    loops: tuple[str, ...] = ()


class FleetInterrupted(KeyboardInterrupt):
    """Ctrl-C or SIGTERM during a run: the cluster is stopped, every finished log kept."""


class Stop:
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
def flag_on_signals(stop: Stop) -> Iterator[None]:
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


def worker_environ(workers: int, cores: int | None = None) -> dict[str, str | None]:
    """What Dask's nanny sets in a local worker's environment before it starts, changed for
    judging (``None`` unsets).  Dask's ``MALLOC_TRIM_THRESHOLD_=65536`` (to hand freed memory
    back to the system) also turns off glibc's adaptive mmap threshold, so every array over
    128 kB of a log's judging is mapped and unmapped afresh: on a 1-hour log 8-12 x the page
    faults and 0.3-0.7 CPU-s of system time on top of 1.5 s (docs/explanation/fleet-scaling.md);
    without it a worker judges as `monitor detect` does.  And numba's parallel loops get the
    worker's share of the cores, not every core each, so N workers do not run N x cores
    threads (a variable the user set keeps their value)."""
    cores = cores or os.cpu_count() or 1
    return {"MALLOC_TRIM_THRESHOLD_": None, "NUMBA_NUM_THREADS": str(max(1, cores // workers))}


@contextmanager
def local_cluster(
    workers: int, dashboard_address: str | None = "127.0.0.1:0", dask_default: bool = False
) -> Iterator[Any]:
    """A LocalCluster of ``workers`` single-threaded worker processes with
    :func:`worker_environ` (or Dask's default environment, as `dask worker` starts them;
    closed afterwards).  The nanny writes its variables into this process's environment
    too; they are put back, so a second cluster gets its own."""
    import dask
    from distributed import LocalCluster

    key = "distributed.nanny.pre-spawn-environ"
    env = {} if dask_default else {f"{key}.{k}": v for k, v in worker_environ(workers).items()}
    saved = dict(os.environ)
    try:
        with _quiet_workers(), dask.config.set(env):
            cluster = LocalCluster(
                n_workers=workers,
                threads_per_worker=1,
                processes=True,
                dashboard_address=dashboard_address,
            )
    finally:
        os.environ.clear()
        os.environ.update(saved)
    with cluster:
        yield cluster


@contextmanager
def client(opts: RunOptions, say: Say) -> Iterator[Any]:
    """A Dask client: on ``opts.scheduler``, or on a LocalCluster closed afterwards."""
    from distributed import Client

    with ExitStack() as stack:
        if opts.scheduler:
            client = Client(opts.scheduler, timeout="30s")
            n = len(client.scheduler_info()["workers"])
            say(f"fleet: Dask scheduler {opts.scheduler}, {n} workers")
        else:
            cluster = stack.enter_context(local_cluster(opts.workers))
            client = Client(cluster)
            say(f"fleet: Dask LocalCluster, {opts.workers} workers")
        if client.dashboard_link:
            say(f"fleet: Dask dashboard {client.dashboard_link}")
        try:
            yield client
        finally:
            # What Dask logs while it stops (workers it kills, tasks it drops, mid-run after
            # a Ctrl-C) is not for the user: the run's own lines say what happened.
            for name in ("distributed", "tornado", "asyncio"):
                logging.getLogger(name).setLevel(logging.CRITICAL)
            client.close()


def wait(futures: list[Any], stop: Stop, progress: Progress) -> None:
    """Until every future is done, checking ``stop`` and redrawing the progress."""
    while not all(f.done() for f in futures):
        stop.check()
        progress.refresh()
        time.sleep(0.1)
    stop.check()
