"""`monitor fleet run`'s local workers: freed memory is reused as in `monitor detect`'s own
process (not mapped afresh for every array, as Dask's default MALLOC_TRIM_THRESHOLD_ made
it), numba's threads are shared out between the workers, and the client's own environment
is left as it was."""

from __future__ import annotations

import os
import resource

from monitor.fleet import cluster
from monitor.fleet.cluster import RunOptions

MIB = 1 << 20
PAGE = resource.getpagesize()
ROUNDS = 200


def _probe() -> dict:
    """In a worker: minor page faults of this thread over ROUNDS arrays of 1 MiB, each
    written whole and freed, and numba's thread count."""
    import numba
    import numpy as np

    before = resource.getrusage(resource.RUSAGE_THREAD).ru_minflt
    for _ in range(ROUNDS):
        a = np.ones(MIB // 8)
        del a
    faults = resource.getrusage(resource.RUSAGE_THREAD).ru_minflt - before
    return {"faults": faults, "numba_threads": numba.get_num_threads()}


def test_workers_reuse_freed_memory_and_share_the_cores(monkeypatch):
    for name in ("MALLOC_TRIM_THRESHOLD_", "NUMBA_NUM_THREADS"):
        monkeypatch.delenv(name, raising=False)
    environ = dict(os.environ)
    with cluster.client(RunOptions(workers=2), say=lambda _m: None) as client:
        probes = client.run(_probe)
    assert len(probes) == 2
    # A 1 MiB array mapped afresh faults in every page of it: 256 of 4 KiB, 200 times over.
    fresh = ROUNDS * MIB // PAGE
    for p in probes.values():
        assert p["faults"] < fresh / 10, p
        assert p["numba_threads"] == max(1, (os.cpu_count() or 1) // 2)
    assert dict(os.environ) == environ


def test_a_worker_gets_its_share_of_the_cores():
    assert cluster.worker_environ(2, cores=8) == {
        "MALLOC_TRIM_THRESHOLD_": None,
        "NUMBA_NUM_THREADS": "4",
    }
    assert cluster.worker_environ(4, cores=2)["NUMBA_NUM_THREADS"] == "1"
