"""`monitor fleet run` reads only regular files inside the fleet folder, one run holds a
results folder at a time, and a full disk under RESULTS is one line and an exit code."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from monitor.fleet.lock import results_lock
from monitor.resources import resource_path
from tests.fleet_support import env

LINK = "refused: a symbolic link, not followed (only files inside the fleet folder are read)"


def _fleet_run(fleet: Path, out: Path, timeout_s: float = 300) -> subprocess.CompletedProcess:
    # A bound, not a timing: before, a FIFO or a /dev/zero link hung the run forever.
    return subprocess.run(
        [
            sys.executable,
            "-m",
            "monitor",
            "fleet",
            "run",
            str(fleet),
            "--out",
            str(out),
            "--isolation",
            "none",
        ],
        capture_output=True,
        text=True,
        env=env(),
        timeout=timeout_s,
    )


def _hostile(where: Path) -> Path:
    """A fleet whose every entry lies outside it or is no file (nothing to judge: no
    cluster starts), beside a folder it must not read."""
    outside = where / "outside"
    (outside / "logs").mkdir(parents=True)
    (outside / "secret.log").write_text("SECRET first line of a file outside the fleet\n")
    (outside / "logs" / "day01.log").write_text("SECRET (0.0) can0 123#00\n")
    f = where / "fleet"
    for d in ("M01/logs", "M03", "M04/commissioning", "M04/logs"):
        (f / d).mkdir(parents=True)
    (f / "M01" / "logs" / "day01.log").symlink_to(outside / "secret.log")
    os.mkfifo(f / "M01" / "logs" / "day02.log")
    (f / "M01" / "logs" / "day03.log").symlink_to("/dev/zero")
    (f / "M01" / "logs" / "day04.log").mkdir()
    (f / "M02").symlink_to(outside, target_is_directory=True)  # a linked machine folder
    (f / "M03" / "logs").symlink_to(outside / "logs", target_is_directory=True)
    (f / "M04" / "commissioning" / "normal.log").symlink_to(outside / "secret.log")
    return f


def test_links_fifos_devices_and_folders_are_refused_each_a_row_and_none_is_read(tmp_path):
    f = _hostile(tmp_path)
    out = tmp_path / "results"
    proc = _fleet_run(f, out, timeout_s=120)
    assert proc.returncode == 3, proc.stderr
    got = {r["log"]: r for r in pq.read_table(out / "logs.parquet").to_pylist()}
    assert {log: r["error"] for log, r in got.items()} == {
        "M01/logs/day01.log": LINK,
        "M01/logs/day02.log": "refused: a FIFO (named pipe), not a file",
        "M01/logs/day03.log": LINK,
        "M01/logs/day04.log": "refused: a folder, not a file",
        "M02/": LINK,
        "M03/logs/": LINK,
        "M04/commissioning/normal.log": LINK,
        "M04/logs/": "no logs (expected FLEET/<machine>/logs/*.log|*.csv)",
    }
    assert all(r["verdict"] == "not_judged" and r["sha256"] is None for r in got.values())
    assert got["M02/"]["machine"] == "M02"
    assert "SECRET" not in (out / "logs.parquet").read_bytes().decode("latin-1")
    assert "SECRET" not in proc.stderr
    assert "fleet: 8 logs: 0 judged, 0 not judged, 8 failed (M01/logs/day01.log: " in proc.stderr


def test_a_second_run_on_held_results_stops_at_once_in_one_line(tmp_path):
    f = tmp_path / "fleet"
    (f / "M01" / "logs").mkdir(parents=True)
    out = tmp_path / "results"
    with results_lock(out):
        busy = _fleet_run(f, out)
    assert busy.returncode == 2, busy.stderr
    assert busy.stderr.strip().splitlines() == [
        f"monitor fleet: error: {out}: another `monitor fleet run` is writing these results "
        f"(pid {os.getpid()}, started "
        + busy.stderr.split(", started ")[1].split(")")[0]
        + "); wait for it to end, or give another --out"
    ]
    assert not (out / "logs.parquet").exists() and not (out / "parts").exists()
    free = _fleet_run(f, out)  # released: the next run goes ahead
    assert free.returncode == 3 and "1 failed (M01/logs/: no logs" in free.stderr


def _can_mount() -> str | None:
    if os.geteuid() != 0:
        return "mounting a tmpfs needs root"
    if shutil.which("mount") is None:
        return "no mount command"
    return None


@pytest.mark.skipif(_can_mount() is not None, reason=str(_can_mount()))
def test_a_full_disk_under_results_is_one_line_and_exit_3(tmp_path):
    # RESULTS on a real 512 KiB tmpfs: the default model (~0.8 MB) that judges a machine
    # without commissioning does not fit; ENOSPC comes from the kernel, mid-run, with the
    # cluster up.  Before: a traceback.
    disk = tmp_path / "disk"
    disk.mkdir()
    mounted = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=512k", "tmpfs", str(disk)],
        capture_output=True,
        text=True,
    )
    if mounted.returncode:
        pytest.skip(f"cannot mount a tmpfs here: {mounted.stderr.strip()}")
    try:
        f = tmp_path / "fleet"
        (f / "M01" / "logs").mkdir(parents=True)
        shutil.copy(resource_path("replay", "normal.log"), f / "M01" / "logs" / "day01.log")
        proc = _fleet_run(f, disk / "results")
    finally:
        subprocess.run(["umount", "-l", str(disk)], check=True)
    assert proc.returncode == 3, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert lines[-1] == (
        f"monitor fleet: error: {disk / 'results'}: cannot write the results: "
        "No space left on device; finished logs are kept, run again once it "
        "can be written"
    )
    assert all(ln.startswith("fleet: ") for ln in lines[:-1]), proc.stderr
