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
