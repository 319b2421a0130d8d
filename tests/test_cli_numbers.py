"""Command-line numbers range-checked while parsing (issue 20): NaN, inf and absurd sizes
are exit 2 naming the option, before any work."""

# ruff: noqa: E501
from __future__ import annotations

import pytest

from monitor.cli import main


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (
            ["simulate", "--duration", "inf"],
            "argument --duration: must be a number within 0.01..7200 s, got 'inf'",
        ),
        (
            ["simulate", "--duration", "1e9"],
            "argument --duration: must be within 0.01..7200 s, got 1e9 (the run is held in memory",
        ),
        (["simulate", "--duration", "nan"], "argument --duration: must be a number"),
        (
            ["simulate", "--duration", "5", "--seed", "-1"],
            "argument --seed: must be within 0..4294967295, got -1",
        ),
        (
            ["simulate", "--duration", "5", "--seed", "1.5"],
            "argument --seed: must be a whole number",
        ),
        (
            ["train", "rec.csv", "--window", "1e12"],
            "argument --window: must be within 1..360000, got 1e12",
        ),
        (["train", "rec.csv", "--window", "0"], "argument --window: must be within 1..360000"),
        (
            ["train", "rec.csv", "--isolation-runs", "0"],
            "argument --isolation-runs: must be within 1..100, got 0",
        ),
        (
            ["encode", "x.csv", "--start-time", "nan"],
            "argument --start-time: must be a number within 0..4102444800 s",
        ),
        (
            ["encode", "x.csv", "--start-time", "1e20"],
            "argument --start-time: must be within 0..4102444800 s",
        ),
        (["simulate", "--duration", "9" * 400], "argument --duration: must be a number"),
    ],
)
def test_cli_numbers_are_range_checked(tmp_path, capsys, argv, message) -> None:
    out = tmp_path / {"train": "m.npz", "encode": "x.log"}.get(argv[0], "x.csv")
    assert main([*argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.splitlines()[-1]) < 200
    assert not out.exists()
