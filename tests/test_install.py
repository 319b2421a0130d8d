"""A non-editable install runs from any directory: package data travels with the wheel."""

from __future__ import annotations

import os
import subprocess
import sys
import venv
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    root = tmp_path_factory.mktemp("install")
    wheels = root / "wheels"
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(wheels), str(REPO)],
        check=True,
    )
    env_dir = root / "venv"
    # The venv borrows numpy, numba, python-can, ... from this interpreter (no network);
    # only the project itself is installed into it, from the wheel.
    venv.EnvBuilder(system_site_packages=True, with_pip=False).create(env_dir)
    py = env_dir / "bin" / "python"
    wheel = next(wheels.glob("*.whl"))
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "--python",
            str(py),
            "install",
            "--no-deps",
            "-q",
            "--force-reinstall",
            str(wheel),
        ],
        check=True,
    )
    work = root / "elsewhere"
    work.mkdir()
    return py, work


def _run(py: Path, work: Path, *args: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    return subprocess.run(
        [str(py), "-m", "monitor", *args],
        cwd=work,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )


def test_installed_package_is_the_one_used(installed):
    py, work = installed
    out = subprocess.run(
        [str(py), "-c", "import monitor; print(monitor.__file__)"],
        cwd=work,
        env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"},
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert str(py.parents[1]) in out


def test_installed_demo_and_detect_run_from_any_directory(installed):
    py, work = installed
    demo = _run(py, work, "demo")
    assert demo.returncode == 0, demo.stderr
    assert "fault" in (demo.stdout + demo.stderr).lower()
    # The demo's files live in a temporary folder it removes: it must not print their path.
    assert "removed on exit" in demo.stdout and "events.jsonl" not in demo.stdout
    log = work / "run.log"
    # Longer than the shipped model's 30 s J window, so that the log is judged (exit 0).
    sim = _run(py, work, "simulate", "--duration", "40", "--seed", "3", "--out", str(log))
    assert sim.returncode == 0, sim.stderr
    det = _run(py, work, "detect", str(log), "--summary", "s.json", "--j-every", "0")
    assert det.returncode == 0, det.stderr
    assert (work / "s.json").is_file()


def test_every_package_of_the_tree_is_in_the_wheel_list():
    """A package missing from pyproject's list works in a checkout and fails once installed."""
    import tomllib

    listed = set(tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"][
        "packages"
    ])
    found = {
        ".".join(p.parent.relative_to(REPO).parts)
        for p in (REPO / "monitor").rglob("__init__.py")
        if "__pycache__" not in p.parts
    }
    assert found - listed == set(), "add these to [tool.setuptools] packages in pyproject.toml"
