"""Commands import only what they use: `monitor --help`, a subcommand's --help, an argument
error and `monitor replay` never load numba or scipy (seconds and ~100 MB on a controller)."""

from __future__ import annotations

import json
import subprocess
import sys

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
    out = subprocess.run([sys.executable, "-c", PROBE, json.dumps(argv)],
                         capture_output=True, text=True, check=False)  # fmt: skip
    heavy = json.loads(out.stderr.strip().splitlines()[-1])
    assert heavy == [], out.stderr


def test_warm_up_fills_the_cache_so_the_next_start_compiles_nothing(tmp_path) -> None:
    env = {**__import__("os").environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    runs = [subprocess.run([sys.executable, "-m", "monitor", "warm-up"], capture_output=True,
                           text=True, env=env, check=True).stderr for _ in range(2)]  # fmt: skip
    first, second = (r.strip().splitlines()[-1] for r in runs)
    assert "0 signatures loaded from the cache" in first and " 0 compiled" not in first
    assert " 0 compiled" in second, second
    assert str(tmp_path / "cache") in second
    assert any((tmp_path / "cache").rglob("*.nbi"))  # numba's cache index files
