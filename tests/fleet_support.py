"""A small simulated fleet for the fleet tests (60 s daily logs, 180 s commissioning)."""

from __future__ import annotations

import contextlib
import fcntl
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from monitor.fleet.simulate import FleetPlan, simulate_fleet

ROOT = Path(__file__).resolve().parents[1]
PLAN = FleetPlan(machines=3, days=2, seed=7, log_s=60.0, commissioning_s=180.0)


def make_fleet(where: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """M01 piston wear, M02 spool wear, M03 frozen QP; 2 days each: ``where/fleet``, a copy
    of the one fleet of PLAN simulated per test session (its seed makes it the same every
    time), so test_fleet, test_fleet_browser and test_fleet_scheduler simulate it once,
    not once each.  Under pytest-xdist the first worker to ask simulates it, under a lock in
    the session's temporary folder its workers share, and the others wait and copy it."""
    base = tmp_path_factory.getbasetemp()
    shared = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base
    built = shared / "fleet-support-plan"
    with open(shared / "fleet-support-plan.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        if not (built / "complete").exists():
            shutil.rmtree(built, ignore_errors=True)
            simulate_fleet(built / "fleet", PLAN, say=lambda _m: None)
            (built / "complete").touch()
    return copy_fleet(built / "fleet", where / "fleet")


def copy_fleet(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst


def env() -> dict[str, str]:
    e = dict(os.environ)
    e["PYTHONPATH"] = str(ROOT) + os.pathsep + e.get("PYTHONPATH", "")
    return e


def fleet_cmd(*args: str) -> list[str]:
    return [sys.executable, "-m", "monitor", "fleet", "run", *args, "--isolation", "none"]


def rows(results: Path) -> list[dict]:
    return pq.read_table(results / "logs.parquet").to_pylist()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for(cond, what: str, proc: subprocess.Popen | None = None, limit_s: float = 600.0):
    """Poll ``cond`` until true; fail naming ``what`` if ``proc`` ends first or at the limit
    (a generous bound against a hung test, not a timing check)."""
    end = time.monotonic() + limit_s
    while not cond():
        if proc is not None and proc.poll() is not None:
            raise AssertionError(f"process ended (rc {proc.returncode}) before {what}")
        if time.monotonic() > end:
            raise AssertionError(f"gave up waiting for {what}")
        time.sleep(0.1)


def kill(proc: subprocess.Popen) -> None:
    """SIGKILL a process started with ``start_new_session`` and everything it started."""
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
