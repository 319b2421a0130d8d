"""The controller's wheel (`monitor build-controller`): the daemon's tick runs from it with
numba made unimportable, and decides exactly as `monitor detect` (numba's JIT, here)."""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
import zipfile
from email.parser import Parser
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent

# numba and llvmlite cannot be imported (as on a controller without them), then the daemon's
# code path on a virtual bus with the shipped spool-wear log replayed, as test_live_e2e does.
NO_NUMBA = """
import json, sys
class NoNumba:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in ("numba", "llvmlite"):
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None
sys.meta_path.insert(0, NoNumba())
if sys.argv[1] == "warm-up":  # a command that needs numba's JIT
    import runpy
    sys.argv = ["monitor", "warm-up"]
    runpy.run_module("monitor", run_name="__main__")
from pathlib import Path
from live_support import live_config, replay_settled, run_daemon
from monitor.jit import aot
from monitor.resources import resource_path
log = resource_path("replay", "spool_wear.log")
daemon, events, frames, counts = run_daemon(live_config(Path(sys.argv[1])), replay_settled(log))
print(json.dumps({"numba": sorted({m.split(".")[0] for m in sys.modules} & {"numba", "llvmlite"}),
                  "module": aot.loaded_from(), "events": events}))
"""


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """`monitor build-controller` of this tree into a folder of its own."""
    if shutil.which("g++") is None:  # numba's pycc compiles through distutils' C++ driver
        pytest.skip("no C++ compiler (g++): the kernels cannot be compiled ahead of time here")
    if importlib.util.find_spec("numba.pycc") is None:
        pytest.skip("numba.pycc is not available here: nothing compiles ahead of time")
    out = tmp_path_factory.mktemp("controller")
    done = subprocess.run(
        [sys.executable, "-m", "monitor", "build-controller", "--out", str(out)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    (found,) = out.glob("*.whl")
    return found


def test_the_controllers_wheel_carries_the_kernels_and_requires_no_numba(wheel: Path) -> None:
    tag = f"cp{sys.version_info.major}{sys.version_info.minor}"
    assert f"-{tag}-{tag}-" in wheel.name  # a compiled part: this Python's ABI, not py3-none
    with zipfile.ZipFile(wheel) as z:
        names = z.namelist()
        meta = Parser().parsestr(z.read(next(n for n in names if n.endswith("/METADATA"))).decode())
    compiled = [n for n in names if n.startswith("monitor/jit/compiled/")]
    assert any(n.endswith(".so") for n in compiled) and any(n.endswith(".json") for n in compiled)
    needs = [r for r in meta.get_all("Requires-Dist") if "extra ==" not in r]
    assert needs and not [r for r in needs if r.lower().startswith(("numba", "llvmlite"))]


def test_the_daemon_from_the_wheel_without_numba_gives_detects_events(
    wheel: Path, tmp_path: Path
) -> None:
    from live_support import assert_same_events

    from monitor.config.settings import load_config
    from monitor.detection.offline import detect
    from monitor.model.modelfile import load_model
    from monitor.resources import resource_path
    from monitor.sampling.read import read_recording

    site = tmp_path / "site"
    with zipfile.ZipFile(wheel) as z:
        z.extractall(site)
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(site), str(TESTS)]),
        "NUMBA_CACHE_DIR": str(tmp_path / "no-cache"),  # no warm-up module to fall back on
    }
    out = subprocess.run(
        [sys.executable, "-c", NO_NUMBA, str(tmp_path)],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,  # not the source tree: the wheel's monitor is imported
        check=False,
    )
    assert out.returncode == 0, out.stderr[-3000:]
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["numba"] == []
    assert got["module"] is not None
    assert Path(got["module"]).parent == site / "monitor" / "jit" / "compiled"
    cfg = load_config()
    rec = read_recording(resource_path("replay", "spool_wear.log"))
    offline = detect(load_model(cfg.model), rec, cfg.alarm, cfg.horizon, gating=cfg.gating)
    assert [(e["state"], e["fault"]) for e in offline.events] == [
        ("normal", None),
        ("fault", "spool_wear"),
    ]
    assert_same_events(got["events"], offline)

    # A command the wheel has no compiled kernels for: one line, exit 2, no traceback.
    warm = subprocess.run(
        [sys.executable, "-c", NO_NUMBA, "warm-up"],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        check=False,
    )
    assert warm.returncode == 2, warm.stderr[-3000:]
    assert warm.stderr.strip().splitlines()[-1].startswith("monitor warm-up: error: needs numba")
    assert "Traceback" not in warm.stderr
