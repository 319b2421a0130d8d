"""A small simulated fleet for the fleet tests (60 s daily logs, 180 s commissioning)."""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pyarrow.parquet as pq

from monitor.fleet.simulate import FleetPlan, simulate_fleet

ROOT = Path(__file__).resolve().parents[1]
PLAN = FleetPlan(machines=3, days=2, seed=7, log_s=60.0, commissioning_s=180.0)


def make_fleet(where: Path) -> Path:
    """M01 piston wear, M02 spool wear, M03 frozen QP; 2 days each."""
    fleet = where / "fleet"
    simulate_fleet(fleet, PLAN, say=lambda _m: None)
    return fleet


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
