"""A model file knows its loop and machine: one trained on another loop or machine is refused
for a config's loop with both named (``monitor detect`` and the daemon's loop loading); an
old file without the record loads as unknown."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest
from model_support import SHIPPED, craft_model

from monitor.cli import main
from monitor.config.layout import row_layout
from monitor.config.settings import load_config
from monitor.errors import ModelFileError
from monitor.io.recording import Recording
from monitor.live.loops import Loop
from monitor.model.machinecard import ModelCard
from monitor.model.modelfile import load_model, save_model
from monitor.resources import resource_path

REFERENCE = {
    "bore_mm": 63.0,
    "rod_mm": 36.0,
    "mass_kg": 400.0,
    "gravity_load_n": 6000.0,
    "pump_disp_cc_rev": 11.0,
    "valve_rated_flow_lpm": 20.0,
}  # config/simulator.yaml
BIG = {
    "bore_mm": 90.0,
    "rod_mm": 50.0,
    "mass_kg": 1500.0,
    "gravity_load_n": 15000.0,
    "pump_disp_cc_rev": 16.0,
    "valve_rated_flow_lpm": 35.0,
}  # the attack's machine
LOG = resource_path("replay", "normal.log")


def _card(loop: str | None, params: dict | None):
    def change(header: dict) -> None:
        header["machine"] = {"loop": loop, "parameters": params, "source": "big.yaml"}

    return change


def _two_loops(tmp_path: Path, model: Path, machine: str = "") -> Path:
    """dbc/excavator4.dbc with its boom and stick loops, ``model`` for both."""
    cfg = tmp_path / "two.yaml"
    cfg.write_text(
        f"dbc: {resource_path('dbc', 'excavator4.dbc')}\nmodel: {model}\nloops:\n"
        f"  - {{name: boom, model: {model}{machine}}}\n"
        f"  - {{name: stick, model: {model}, alarm_message: MON_Alarm_Stick, signals: "
        "{SpoolCmd: Stick_SpoolCmd, PumpDispCmd: Stick_PumpDispCmd, PP: Stick_PP, "
        "PA: Stick_PA, PB: Stick_PB, QP: Stick_QP, RodPos: Stick_RodPos}}\n"
    )
    return cfg


def test_a_stick_model_for_the_boom_loop_is_refused_naming_both(tmp_path, capsys) -> None:
    model = craft_model(tmp_path, header_change=_card("stick", None))
    cfg = _two_loops(tmp_path, model)
    rc = main(["detect", str(LOG), "--config", str(cfg), "--loop", "boom"])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "\n" not in err and "Traceback" not in err
    assert err == (
        f"monitor detect: error: {model}: a model of loop 'stick', given to {cfg}: "
        "loops[0], loop 'boom': train one for this loop (monitor train --loop boom)"
    )
    # ... and for the stick loop it loads.
    assert main(["detect", str(LOG), "--config", str(cfg), "--loop", "stick"]) == 3  # no frames


def test_the_daemon_refuses_it_at_loading(tmp_path) -> None:
    model = craft_model(tmp_path, header_change=_card("stick", None))
    cfg = load_config(_two_loops(tmp_path, model))
    from monitor.codec.frames import FrameCodec

    _, views = row_layout(cfg, FrameCodec.from_dbc(cfg.dbc))
    with pytest.raises(ModelFileError, match="a model of loop 'stick', given to .*loop 'boom'"):
        Loop.load(cfg.loops[0], cfg, views[0])
    Loop.load(cfg.loops[1], cfg, views[1])


def test_a_model_of_another_machine_is_refused_naming_both(tmp_path, capsys) -> None:
    model = craft_model(tmp_path, header_change=_card("boom", BIG))
    assert main(["detect", str(LOG), "--model", str(model)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err
    assert "trained on a machine with bore 90 mm, rod 50 mm, mass 1500 kg" in err
    assert (
        "has bore 63 mm, rod 36 mm, mass 400 kg, load 6000 N, pump 11 cc/rev, valve 20 L/min" in err
    )
    assert (
        "(bore_mm, rod_mm, mass_kg, gravity_load_n, pump_disp_cc_rev, "
        "valve_rated_flow_lpm differ)" in err
    )


def test_a_model_trained_on_flows_the_machine_cannot_deliver_is_refused(tmp_path, capsys) -> None:
    """No record of its machine (an old file), but its training envelope saw QP up to
    35 L/min: the reference pump gives 11 cc/rev x 2200 rpm = 24.2 L/min, and 35 is more
    than 1.3 x that (31.46)."""

    def change(header: dict) -> None:
        v = header["validity"]
        v["max"][v["signals"].index("QP")] = 35.0

    model = craft_model(tmp_path, header_change=change)
    assert main(["detect", str(LOG), "--model", str(model)]) == 2
    err = capsys.readouterr().err.strip()
    assert f"{model}: trained on QP up to 35 L/min, more than 1.3 x the 24.2 L/min of" in err
    assert "another machine" in err and "\n" not in err


def test_an_old_model_without_the_record_loads_as_unknown(tmp_path, caplog) -> None:
    # The shipped model records the machine it was commissioned on: without the record, a
    # file from before it.
    model = load_model(craft_model(tmp_path, header_change=lambda h: h.pop("machine")))
    assert model.card is None
    cfg = load_config()
    from monitor.config.layout import check_loop_model

    with caplog.at_level(logging.INFO, logger="monitor"):
        check_loop_model(model, cfg.monitored_loops[0], cfg)
    assert "records no loop or machine" in caplog.text and "unknown" in caplog.text


def test_the_record_round_trips_and_train_writes_the_configured_one(tmp_path) -> None:
    from monitor.cli.train import _card as train_card

    model = load_model(SHIPPED)
    n = 100
    cols = {
        s: np.full(n, 20.0)
        for s in ("SpoolCmd", "PumpDispCmd", "EngineSpeed", "OilTemp", "PP", "PA", "PB", "QP")
    }
    rec = Recording(np.arange(n) * 0.01, cols)
    model.card = train_card(load_config(), None, [rec])
    assert model.card.loop == "boom" and model.card.machine == REFERENCE
    save_model(tmp_path / "m.npz", model)
    assert load_model(tmp_path / "m.npz").card == model.card
    # Recordings the configured machine cannot produce are refused before training.
    big = Recording(np.arange(n) * 0.01, {**cols, "QP": np.full(n, 35.0)}, source="big.csv")
    with pytest.raises(ModelFileError, match="^big.csv: shows QP up to 35 L/min, more than 1.3 x"):
        train_card(load_config(), None, [rec, big])


def test_a_bad_record_is_an_inconsistent_model_file(tmp_path) -> None:
    model = craft_model(tmp_path, header_change=_card("boom", {"bore_mm": "wide"}))
    with pytest.raises(ModelFileError, match="inconsistent model file .*machine.parameters"):
        load_model(model)
    assert ModelCard.from_dict({"loop": None}).machine is None
