"""Every output path is checked when the command line is read, before any work: a missing
folder or a folder given as a file is exit 2 naming the option, never a run thrown away."""

from __future__ import annotations

from pathlib import Path

import pytest

from monitor.cli import main
from monitor.resources import resource_path

LOG = str(resource_path("replay", "normal.log"))


def commands(bad: str) -> list[list[str]]:
    return [
        ["detect", LOG, "--summary", bad],
        ["detect", LOG, "--events", bad],
        ["detect", LOG, "--plot", bad],
        ["train", LOG, "--out", bad],
        ["simulate", "--duration", "5", "--seed", "1", "--out", bad],
        ["encode", "x.csv", "--out", bad],
        ["gap", "--real", LOG, "--json", bad],
        ["gap", "--real", LOG, "--json", "ok.json", "--report", bad + "/sub"],
        ["eval-sim", "--json", bad],
        ["eval-uci", "--train", ".", "--test", ".", "--json", bad],
        ["bench", "--json", bad],
    ]


@pytest.mark.parametrize("argv", commands("/nonexistent-dir/out.x"), ids=lambda a: a[0] + a[-2])
def test_missing_output_folder_is_refused_before_the_work(argv, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "/nonexistent-dir" in err and "does not exist" in err
    assert f"argument {argv[-2]}" in err


def test_a_folder_given_as_the_output_file_is_refused(tmp_path: Path, capsys) -> None:
    assert main(["detect", LOG, "--plot", str(tmp_path)]) == 2
    assert "is a folder, not a file to write" in capsys.readouterr().err
