"""Sim-to-real diagnosis speed (pytest-benchmark; ``python -m pytest benchmarks/test_bench_gap.py
--benchmark-enable``).

Issue 18's goal: a 5-minute recording diagnosed in <= 15 s of CPU on the 2-core machine.  The
case runs ``monitor gap`` in a subprocess, as a user does, on a simulated 5-minute boom
recording with a 400 N Coulomb friction, and records the child's CPU seconds
(``gap_cpu_s``, user + system from ``getrusage``) beside the wall time pytest-benchmark takes.
"""

from __future__ import annotations

import resource
import subprocess
import sys

import pytest


def _cpu_children_s() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    path = tmp_path_factory.mktemp("gap") / "friction_300s.csv"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "monitor",
            "simulate",
            "--duration",
            "300",
            "--seed",
            "3",
            "--effect",
            "cylinder_friction:coulomb_n=400",
            "--out",
            str(path),
        ],
        check=True,
        capture_output=True,
    )
    return path


def test_gap_5min_cpu(benchmark, recording, tmp_path):
    out = tmp_path / "gap.json"
    cpu: list[float] = []

    def run() -> None:
        before = _cpu_children_s()
        subprocess.run(
            [
                sys.executable,
                "-m",
                "monitor",
                "gap",
                "--real",
                str(recording),
                "--json",
                str(out),
                "--quiet",
            ],
            check=True,
            capture_output=True,
        )
        cpu.append(_cpu_children_s() - before)

    benchmark.pedantic(run, rounds=1, iterations=1)
    benchmark.extra_info["gap_cpu_s"] = round(cpu[-1], 2)
    assert out.exists()
