"""Commands import only what they use: `monitor --help`, a subcommand's --help, an argument
error and `monitor replay` never load numba or scipy (seconds and ~100 MB on a controller)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

PROBE = """
import json, runpy, sys
sys.argv = ["monitor", *json.loads(sys.argv[1])]
try:
    runpy.run_module("monitor", run_name="__main__")
except SystemExit:
    pass
heavy = sorted({m.split(".")[0] for m in sys.modules} & {"numba", "scipy", "matplotlib"})
print(json.dumps(heavy), file=sys.stderr)
"""


@pytest.mark.parametrize(
    "argv",
    [
        ["--help"],
        [],
        ["detect", "--help"],
        ["detect", "x.log", "--no-such-option"],
        ["train", "--help"],
        ["simulate", "--help"],
        ["eval-sim", "--help"],
        ["eval-uci", "--help"],
        ["run", "--help"],
        ["demo", "--help"],
        ["replay", "--help"],
        ["replay", "missing.log", "--bus", "x", "--interface", "virtual"],
        ["watch", "--help"],
    ],
    ids=lambda a: " ".join(a) or "(none)",
)
def test_help_and_argument_errors_load_no_numba_or_scipy(argv: list[str]) -> None:
    out = subprocess.run(
        [sys.executable, "-c", PROBE, json.dumps(argv)], capture_output=True, text=True, check=False
    )
    heavy = json.loads(out.stderr.strip().splitlines()[-1])
    assert heavy == [], out.stderr


@pytest.fixture(scope="module")
def warm(warm_numba_cache) -> tuple[list[str], Path]:
    """``monitor warm-up`` twice into a cache of its own: (stderr of each run, cache dir)."""
    return warm_numba_cache


def _line(stderr: str, text: str) -> str:
    return next(line for line in stderr.splitlines() if text in line)


def test_warm_up_fills_the_cache_so_the_next_start_compiles_nothing(warm) -> None:
    runs, cache = warm
    first, second = (_line(r, "signatures loaded from the cache") for r in runs)
    assert "0 signatures loaded from the cache" in first and " 0 compiled" not in first
    assert " 0 compiled" in second, second
    assert str(cache) in second
    assert any(cache.rglob("*.nbi"))  # numba's cache index files


# A process that ticks the rows of the spool-wear log (read here: the bulk reader is numba's)
# the way the daemon does and says whether it loaded numba.
TICKS = """
import json, sys
import numpy as np
from monitor.config.settings import load_config
from monitor.detection.ticker import Ticker, event
from monitor.model.modelfile import load_model
cfg = load_config()
ticker = Ticker(load_model(cfg.model), cfg.alarm, cfg.horizon, gating=cfg.gating)
rows = np.load(sys.argv[1])
events = []
for row in rows:
    tick = ticker.tick(row)
    if tick.changed:
        events.append(event(tick, ticker.fault, ticker.eps0, float(sys.argv[2])))
print(json.dumps({"numba": "numba" in sys.modules, "events": events}))
"""


@pytest.mark.parametrize("aot", ["1", "0"])
def test_the_tick_kernels_compiled_ahead_of_time_decide_as_the_jit(
    warm, aot: str, tmp_path
) -> None:
    """After warm-up the per-tick detector runs without numba (the module pycc built) and
    gives exactly the events of `monitor detect`; with MONITOR_AOT=0 it loads numba."""
    import numpy as np
    from live_support import assert_same_events, rows_of

    from monitor.config.settings import load_config
    from monitor.detection.offline import detect
    from monitor.model.modelfile import load_model
    from monitor.resources import resource_path
    from monitor.sampling.read import read_recording

    runs, cache = warm
    if shutil.which("g++") is None:  # numba's pycc compiles through distutils' C++ driver
        pytest.skip("no C++ compiler (g++): `monitor warm-up` cannot compile the tick kernels")
    # Every kernel declared ``@jit(aot=...)`` in the package's source, counted here apart.
    src = Path(__file__).resolve().parents[1] / "monitor"
    n = sum(p.read_text().count("@jit(aot=True") for p in src.rglob("*.py"))
    want = f"{n} of {n} kernels (live tick, offline detection) compiled ahead of time"
    assert n >= 20 and want in runs[-1], runs[-1]
    rec = read_recording(resource_path("replay", "spool_wear.log"))
    np.save(tmp_path / "rows.npy", rows_of(rec))
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "MONITOR_AOT": aot}
    out = subprocess.run(
        [sys.executable, "-c", TICKS, str(tmp_path / "rows.npy"), repr(rec.meta["start_time_s"])],
        capture_output=True,
        text=True,
        env=env,
        check=True,
    )
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["numba"] is (aot == "0")
    cfg = load_config()
    offline = detect(load_model(cfg.model), rec, cfg.alarm, cfg.horizon, gating=cfg.gating)
    assert [e["state"] for e in offline.events] == ["normal", "fault"]
    assert_same_events(got["events"], offline)


# `monitor detect` in a process of its own: its summary, events, and whether numba loaded.
DETECT = """
import json, runpy, sys
sys.argv = ["monitor", "detect", sys.argv[1], "--summary", sys.argv[2], "--events", sys.argv[3],
            "--j-every", "0"]
try:
    runpy.run_module("monitor", run_name="__main__")
except SystemExit:
    pass
print(json.dumps({"numba": "numba" in sys.modules}))
"""


def test_monitor_detect_after_warm_up_loads_no_numba_and_judges_as_the_jit(warm, tmp_path) -> None:
    """The offline kernels (candump scan, sample clock, DGRNN over a series on one thread,
    J, B) compiled ahead of time give `monitor detect` the JIT's verdict, events and alarm
    times; only sums may differ in the last bits (pycc compiles without fast-math)."""
    from live_support import assert_same_events

    from monitor.resources import resource_path

    runs, cache = warm
    if shutil.which("g++") is None:
        pytest.skip("no C++ compiler (g++): `monitor warm-up` cannot compile the kernels")
    log = resource_path("replay", "spool_wear.log")
    got = {}
    for aot in ("1", "0"):
        summary, events = tmp_path / f"s{aot}.json", tmp_path / f"e{aot}.jsonl"
        env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "MONITOR_AOT": aot}
        out = subprocess.run(
            [sys.executable, "-c", DETECT, str(log), str(summary), str(events)],
            capture_output=True,
            text=True,
            env=env,
            check=True,
        )
        probe = json.loads(out.stdout.strip().splitlines()[-1])
        assert probe["numba"] is (aot == "0"), out.stderr
        got[aot] = (
            json.loads(summary.read_text()),
            [json.loads(x) for x in events.read_text().splitlines()],
        )
    (s_aot, e_aot), (s_jit, e_jit) = got["1"], got["0"]
    assert s_aot["verdict"] == s_jit["verdict"] == "fault"
    assert s_aot["first_alarm_t"] == s_jit["first_alarm_t"]
    assert s_aot["fault"] == s_jit["fault"] == "spool_wear"
    for key in ("max_J", "max_B", "max_level"):
        assert s_aot[key] == pytest.approx(s_jit[key], rel=1e-9), key
    assert_same_events(e_aot, e_jit)


GUARD = """
import json, sys
import numpy as np
from monitor.model.residual import _j_series
a = _j_series(np.ones(10), 3, 1000)
aot_only = "numba" not in sys.modules
b = _j_series(np.ones(10, dtype=np.float32), 3, 1000)  # pycc would crash on these
c = _j_series(np.ones(20)[::2], 3, 1000)
print(json.dumps({"aot_only": aot_only, "numba": "numba" in sys.modules,
                  "out": [np.nan_to_num(x, nan=-1.0).tolist() for x in (a, b, c)]}))
"""


def test_an_ahead_of_time_kernel_hands_other_argument_types_to_the_jit(warm) -> None:
    """pycc's functions trust their arguments; the guard sends a float32 or a strided array
    to the JIT instead, which gives the same values (a crash is the failure)."""
    runs, cache = warm
    if shutil.which("g++") is None:
        pytest.skip("no C++ compiler (g++): `monitor warm-up` cannot compile the kernels")
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "MONITOR_AOT": "1"}
    out = subprocess.run(
        [sys.executable, "-c", GUARD], capture_output=True, text=True, env=env, check=True
    )
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["aot_only"] and got["numba"]
    expected = [-1.0, -1.0] + [1.0] * 8  # the mean of three ones, from the third sample on
    assert got["out"] == [expected] * 3
