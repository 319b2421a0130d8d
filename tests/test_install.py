"""A non-editable install runs from any directory: package data travels with the wheel."""

from __future__ import annotations

import json
import os
import re
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
    # The demo's sample clock is the log's: its speed changes only the wall time (the 90 s
    # log in 1.5 s, not 18 s at the default 5x).
    demo = _run(py, work, "demo", "--speed", "60")
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

    listed = set(
        tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]
    )
    found = {
        ".".join(p.parent.relative_to(REPO).parts)
        for p in (REPO / "monitor").rglob("__init__.py")
        if "__pycache__" not in p.parts
    }
    assert found - listed == set(), "add these to [tool.setuptools] packages in pyproject.toml"


# The controller's install (`pip install .`) has none of the extras: a subprocess in which
# importing them fails stands for it (the suite's own environment has them all).
_LEAN = """
import sys
BLOCKED = {"dask", "distributed", "pyarrow", "duckdb", "scipy", "matplotlib", "threadpoolctl"}
class _Blocked:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ModuleNotFoundError(f"No module named {name!r} (blocked)", name=name)
        return None
sys.meta_path.insert(0, _Blocked())
"""
_DAEMON_PACKAGES = (
    "bus",
    "codec",
    "config",
    "detection",
    "io",
    "jit",
    "live",
    "model",
    "sampling",
    "schema",
    "watch",
)
_LEAN_COMMANDS = ("demo", "run", "detect", "replay", "watch", "encode")


def _lean(code: str, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run(
        [sys.executable, "-c", _LEAN + code, *args],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
        cwd=REPO,
    )


def test_the_daemons_modules_and_detect_need_none_of_the_extras(tmp_path):
    from monitor.cli import main
    from monitor.resources import resource_path

    log = str(resource_path("replay", "spool_wear.log"))
    code = f"""
import importlib, json, pkgutil
import monitor
for pkg in {_DAEMON_PACKAGES!r}:
    mod = importlib.import_module("monitor." + pkg)
    for m in pkgutil.walk_packages(mod.__path__, mod.__name__ + "."):
        importlib.import_module(m.name)
for cmd in {_LEAN_COMMANDS!r}:
    importlib.import_module("monitor.cli." + cmd)
from monitor.cli import main
rc = main(["detect", sys.argv[1], "--summary", sys.argv[2], "--j-every", "0", "--events",
           sys.argv[3]])
loaded = sorted(m for m in sys.modules if m.split(".")[0] in BLOCKED)
print(json.dumps({{"rc": rc, "loaded": loaded}}))
"""
    lean = _lean(code, log, str(tmp_path / "lean.json"), str(tmp_path / "lean.jsonl"))
    assert lean.returncode == 0, lean.stderr
    assert json.loads(lean.stdout.splitlines()[-1]) == {"rc": 0, "loaded": []}
    # The same detection as with every extra installed (this process).
    assert (
        main(
            [
                "detect",
                log,
                "--summary",
                str(tmp_path / "full.json"),
                "--j-every",
                "0",
                "--events",
                str(tmp_path / "full.jsonl"),
            ]
        )
        == 0
    )
    for name in ("json", "jsonl"):
        assert (tmp_path / f"lean.{name}").read_text() == (tmp_path / f"full.{name}").read_text()
    assert json.loads((tmp_path / "lean.json").read_text())["fault"] == "spool_wear"


@pytest.mark.parametrize(
    ("args", "extra", "module"),
    [
        (["fleet", "run", "FLEET", "--out", "RESULTS"], "fleet", "distributed"),
        (["fleet", "report", "RESULTS", "--out", "PAGE"], "fleet", "pyarrow"),
        (["detect", "LOG", "--plot", "PLOT"], "analysis", "matplotlib"),
        (["simulate", "--duration", "40", "--seed", "1", "--out", "SIM"], "analysis", "scipy"),
    ],
)
def test_a_command_of_an_extra_says_which_extra_in_one_line_and_exit_2(
    tmp_path, args, extra, module
):
    from monitor.resources import resource_path

    (tmp_path / "FLEET" / "M01" / "logs").mkdir(parents=True)
    where = {
        "FLEET": tmp_path / "FLEET",
        "RESULTS": tmp_path / "RESULTS",
        "PAGE": tmp_path / "p",
        "LOG": resource_path("replay", "normal.log"),
        "PLOT": tmp_path / "x.png",
        "SIM": tmp_path / "sim.log",
    }
    argv = [str(where.get(a, a)) for a in args]
    done = _lean("from monitor.cli import main; sys.exit(main(sys.argv[1:]))", *argv)
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip().splitlines() == [
        f"monitor {args[0]}: error: needs the [{extra}] extra ({module} is not installed): "
        f"pip install 'hydraulic-monitor[{extra}]'"
    ]
    assert not any((tmp_path / n).exists() for n in ("RESULTS", "p", "x.png", "sim.log"))


def test_the_default_install_is_the_daemons_and_test_pulls_every_extra():
    import tomllib

    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    names = {re.split(r"[<>=\[ ]", d)[0].lower() for d in project["dependencies"]}
    assert names == {"numpy", "numba", "python-can", "cantools", "pyyaml", "crc", "msgpack"}
    extras = project["optional-dependencies"]
    pulled = next(d for d in extras["test"] if d.startswith("hydraulic-monitor["))
    assert set(pulled.split("[")[1].rstrip("]").split(",")) == set(extras) - {"test"}
