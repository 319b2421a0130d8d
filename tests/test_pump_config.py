"""`pump:` of a monitor config and the CLI's --pump: bad input is one line and exit 2."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from monitor.cli import main
from monitor.config.pump import load_pump, pump_columns
from monitor.config.settings import load_config
from monitor.errors import ConfigError
from monitor.resources import resource_path

SHIPPED = resource_path("config", "excavator4.yaml")


def _config(tmp_path: Path, **edits) -> Path:
    """config/excavator4.yaml with absolute paths and ``edits`` to its top level."""
    doc = yaml.safe_load(SHIPPED.read_text())
    here = SHIPPED.parent
    doc["dbc"] = str((here / doc["dbc"]).resolve())
    doc["model"] = str(here / doc["model"])
    for loop in doc["loops"]:
        loop["model"] = str(here / loop["model"])
    doc["pump"]["model"] = str(here / doc["pump"]["model"])
    for key, value in edits.items():
        if value is None:
            doc.pop(key, None)
        else:
            doc[key] = value
    path = tmp_path / "machine.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def test_the_shipped_config_reads_every_section_of_its_pump() -> None:
    cfg = load_config(SHIPPED)
    model = load_pump(cfg)
    assert model is not None and model.on and cfg.pump is not None
    assert cfg.pump.alarm_message == "MON_Alarm_Pump"
    # The physics of the simulated machine: band 5 bar over 39.6 L/min of full flow.
    assert model.law.flow_coef == pytest.approx(5 / 39.6, rel=0.02)
    cols = pump_columns(
        cfg,
        ("PP", "SpoolCmd", "PA", "PB", "QP")
        + tuple(
            f"{p}_{c}" for p in ("Stick", "Bucket", "Swing") for c in ("SpoolCmd", "PA", "PB", "QP")
        ),
    )
    assert cols.pp == 1 and cols.spool[0] == 2 and cols.qp[-1] == 17


@pytest.mark.parametrize(
    ("pump", "says"),
    [
        ("x.json", "pump must be a mapping"),
        ({"model": "x.json", "colour": 1}, "pump must be a mapping"),
        ({"model": "/nowhere/x.json"}, "no such file"),
        ({"alarm_message": "MON_Alarm_Pump"}, "pump must be a mapping"),
    ],
)
def test_a_bad_pump_section_is_one_config_error(tmp_path, pump, says) -> None:
    with pytest.raises(ConfigError, match=says):
        load_config(_config(tmp_path, pump=pump))


def test_a_pump_model_needs_the_load_sensing_margin_it_was_trained_with(tmp_path) -> None:
    compensated = load_config(
        _config(tmp_path, plausibility={"pump_system": "pressure_compensated"})
    )
    with pytest.raises(ConfigError, match="load_sensing"):
        load_pump(compensated)
    other = load_config(
        _config(tmp_path, plausibility={"pump_system": "load_sensing", "ls_margin_bar": 25})
    )
    with pytest.raises(ConfigError, match="margin of 20 bar"):
        load_pump(other)


def test_cli_pump_mistakes_are_one_line_and_exit_2(tmp_path, capsys) -> None:
    log = tmp_path / "x.csv"
    log.write_text("t\n0\n")
    no_pump = _config(tmp_path, pump=None)
    assert main(["detect", str(log), "--config", str(no_pump), "--pump"]) == 2
    assert "monitor train --pump" in capsys.readouterr().err
    out = str(tmp_path / "p.json")
    assert main(["train", "--pump", str(log), "--config", str(SHIPPED), "--out", out]) == 2
    assert "--held-out" in capsys.readouterr().err
    argv = ["train", "--pump", str(log), "--held-out", str(log), "--loop", "boom", "--out", out]
    assert main(argv) == 2
    assert "leave --loop out" in capsys.readouterr().err
