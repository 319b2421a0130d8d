"""`monitor fleet run --scheduler` against a real `dask scheduler` and two `dask worker`
processes on 127.0.0.1; one worker is killed mid-run and every log still gets one row."""

from __future__ import annotations

import subprocess
import sys

from tests.fleet_support import env, fleet_cmd, free_port, kill, make_fleet, rows, wait_for


def _start(*args: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", *args],
        env=env(),
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )


def test_external_scheduler_and_a_worker_killed_mid_run(tmp_path, tmp_path_factory):
    from distributed import Client

    fleet = make_fleet(tmp_path, tmp_path_factory)
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    procs = [
        _start(
            "distributed.cli.dask_scheduler",
            "--host",
            "127.0.0.1",
            "--port",
            str(port),
            "--dashboard-address",
            "127.0.0.1:0",
        )
    ]
    try:
        for _ in range(2):
            procs.append(
                _start(
                    "distributed.cli.dask_worker",
                    address,
                    "--nthreads",
                    "1",
                    "--no-dashboard",
                    "--host",
                    "127.0.0.1",
                )
            )
        with Client(address, timeout="120s") as c:
            c.wait_for_workers(2, timeout=300)
        out = tmp_path / "results"
        run = subprocess.Popen(
            fleet_cmd(str(fleet), "--out", str(out), "--scheduler", address),
            stderr=subprocess.PIPE,
            text=True,
            env=env(),
        )
        parts = out / "parts"
        wait_for(lambda: parts.is_dir() and any(parts.glob("*.json")), "a finished log", run)
        kill(procs[1])  # one worker dies mid-run; Dask reruns its tasks on the other
        _out, err = run.communicate()
        assert run.returncode == 0, err
        assert f"Dask scheduler {address}" in err
        logs = sorted(r["log"] for r in rows(out))
        assert logs == sorted(p.relative_to(fleet).as_posix() for p in fleet.glob("*/logs/*"))
        assert all(r["error"] is None and r["model"] == "commissioned" for r in rows(out))
    finally:
        for p in procs:
            kill(p)
