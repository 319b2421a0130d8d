"""One clear line for the small user mistakes: no command, a folder as a recording, a CAN
channel that is not up."""

from __future__ import annotations

from pathlib import Path

from monitor.cli import main


def test_monitor_alone_lists_the_commands(capsys) -> None:
    assert main([]) == 2
    err = capsys.readouterr().err
    for command in ("demo", "run", "detect", "train", "replay", "gap"):
        assert command in err


def test_a_folder_as_the_recording_says_so(tmp_path: Path, capsys) -> None:
    assert main(["detect", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith("is a folder; give a recording (.log or .csv) in it")
    assert "no such file" not in err


def test_a_channel_that_is_not_up_names_that_channel(capsys, tmp_path: Path) -> None:
    from monitor.resources import resource_path

    # vcan97 exists nowhere: opening it fails on any host (no CAN support, or no such device).
    rc = main(["replay", str(resource_path("replay", "normal.log")), "--bus", "vcan97"])
    err = capsys.readouterr().err
    assert rc == 2
    assert "vcan97" in err and "can0" not in err and "type vcan" in err


def test_numbers_in_messages_are_plain_numbers_not_numpy_reprs() -> None:
    import numpy as np
    import pytest

    from monitor.errors import ConfigError
    from monitor.model.grnn_core import _check_sigma

    with pytest.raises(ConfigError) as err:
        _check_sigma(np.float64(-5.99))
    assert str(err.value) == "sigma must be a positive finite number, got -5.99"
