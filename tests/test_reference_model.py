"""One rule for "this model was trained on this machine" (``machinecard.reference_reason``):
the model records the machine it was commissioned on (the shipped model: the reference
machine), the run declares the machine it judges (``machine_id`` in the config, a fleet's
machine folder).  A model of another machine withholds its hydraulic alarms and says why,
alike in `monitor detect`, in the daemon on a bus and in the fleet; the machine's own model
(and the shipped config, which declares the reference machine) alarms as before."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from live_support import assert_same_events, live_config, replay_settled, run_daemon

from monitor.cli import main
from monitor.config.settings import load_config
from monitor.errors import ConfigError
from monitor.model.machinecard import REFERENCE_MACHINE, ModelCard, card_for, reference_reason
from monitor.model.modelfile import load_model
from monitor.resources import resource_path

LOG = resource_path("replay", "spool_wear.log")  # a recording of the reference machine
SHIPPED = resource_path("config", "boom_default.model.npz")


def test_the_rule_compares_the_models_machine_with_the_declared_one() -> None:
    shipped = load_model(SHIPPED).card
    assert shipped is not None and shipped.machine_id == REFERENCE_MACHINE
    assert reference_reason(shipped, REFERENCE_MACHINE) is None
    other = reference_reason(shipped, "EX-0042")
    assert other is not None and "shipped reference model" in other and "'EX-0042'" in other
    undeclared = reference_reason(shipped, None)  # a config that names no machine
    assert undeclared is not None and "declares no machine_id" in undeclared
    own = card_for("boom", None, None, "EX-0042")
    assert reference_reason(own, "EX-0042") is None
    assert "commissioned on machine 'EX-0042'" in (reference_reason(own, "EX-0043") or "")
    # A model that records no machine (older files, trained without machine_id): as before.
    assert reference_reason(None, "EX-0042") is None
    assert reference_reason(ModelCard("boom"), None) is None


def test_the_card_keeps_the_id_and_a_card_without_one_is_written_as_before() -> None:
    card = card_for("boom", None, None, "EX-0042")
    assert ModelCard.from_dict(card.to_dict()) == card
    assert "id" not in ModelCard("boom").to_dict()
    with pytest.raises(ValueError, match="machine.id"):
        ModelCard.from_dict({"loop": "boom", "id": 42})


def test_machine_id_is_declared_in_the_config(tmp_path: Path) -> None:
    assert load_config().machine_id == REFERENCE_MACHINE  # the shipped config's machine
    p = tmp_path / "m.yaml"
    p.write_text("machine_id: ' EX-0042 '\n")
    assert load_config(p).machine_id == "EX-0042"
    p.write_text("{}\n")
    assert load_config(p).machine_id is None
    p.write_text("machine_id: 42\n")  # a serial as a number would lose leading zeros
    with pytest.raises(ConfigError, match=r"m\.yaml: machine_id must be a text.*got 42"):
        load_config(p)


def test_train_records_the_configs_machine(tmp_path: Path) -> None:
    from monitor.cli.train import _card

    p = tmp_path / "m.yaml"
    p.write_text("machine_id: EX-0042\n")
    assert _card(load_config(p), None, []).machine_id == "EX-0042"
    assert _card(load_config(), None, []).machine_id == REFERENCE_MACHINE


def _detect(tmp_path: Path, config: Path | None, capsys) -> tuple[int, dict, list[dict], str]:
    summary, events = tmp_path / "s.json", tmp_path / "e.jsonl"
    args = ["detect", str(LOG), "--summary", str(summary), "--events", str(events)]
    code = main([*args, "--j-every", "0", *(["--config", str(config)] if config else [])])
    err = capsys.readouterr().err
    lines = [json.loads(x) for x in events.read_text().splitlines()]
    return code, json.loads(summary.read_text()), lines, err


def _daemon(tmp_path: Path, config: Path | None) -> list[dict]:
    cfg = live_config(tmp_path, config)
    _, events, _, _ = run_daemon(cfg, replay_settled(LOG))
    return events


@pytest.mark.parametrize("declared", [None, "EX-0042"])
def test_detect_and_the_daemon_withhold_alike_on_another_machine(
    declared, tmp_path: Path, capsys
) -> None:
    """The shipped spool-wear log under a config of another machine (EX-0042) or of no
    machine: detect withholds (not_judged, exit 3, the reason) and the daemon, fed the same
    log on a virtual bus, raises no fault either and writes a withheld line at the very
    time detect's summary names; their state changes are the same."""
    config = tmp_path / "m.yaml"
    config.write_text("" if declared is None else f"machine_id: {declared}\n")
    code, s, lines, err = _detect(tmp_path, config, capsys)
    assert code == 3 and s["verdict"] == "not_judged" and s["reference_model"] is True
    assert not s["alarm"] and s["fault"] is None and s["alarm_episodes"] == 0
    w = s["withheld"]
    assert w["first_t"] > 45.0 and w["episodes"] == 1 and w["max_level"] > 1.0
    assert "shipped reference model" in w["reason"] and "monitor train" in w["reason"]
    assert s["not_judged_why"] == w["reason"]
    assert "not judged: judged with the shipped reference model" in err
    assert all(e["state"] != "fault" for e in lines)

    events = _daemon(tmp_path / "live", config)
    states = [e for e in events if "kind" not in e]
    withheld = [e for e in events if e.get("kind") == "withheld"]
    assert all(e["state"] != "fault" for e in states)
    assert [e["t"] for e in withheld] == [w["first_t"]]
    assert withheld[0]["reason"].startswith(w["reason"].split(": a level")[0])
    assert withheld[0]["level"] > 1.0 and withheld[0]["seq"] > 0
    assert_same_events(states, [e for e in lines if e["event"] == "state"])


def test_detect_and_the_daemon_alarm_alike_on_the_reference_machine(tmp_path: Path, capsys) -> None:
    """The shipped config declares the reference machine, whose recording the log is: both
    raise the spool-wear fault at the same time, nothing withheld (the README's and the
    demo's result)."""
    code, s, lines, err = _detect(tmp_path, None, capsys)
    assert code == 0 and s["verdict"] == "fault" and s["fault"] == "spool_wear"
    assert s["reference_model"] is False and s["withheld"] is None
    assert "FAULT from" in err and "reference" not in err
    events = _daemon(tmp_path, None)
    assert not [e for e in events if "kind" in e]
    faults = [e for e in events if e["state"] == "fault"]
    assert faults and faults[0]["t"] == s["first_alarm_t"]
    assert_same_events(events, [e for e in lines if e["event"] == "state"])


def test_fleet_rows_follow_the_same_rule() -> None:
    """A fleet machine without commissioning (M04) judged with the shipped model: its row
    says reference_model and is never a fault; the reference machine's own log is."""
    from monitor.fleet.pipeline import judge_log
    from monitor.fleet.store import log_schema

    assert str(log_schema().field("reference_model").type) == "bool"
    data = SHIPPED.read_bytes()
    row = judge_log(data, str(LOG), None, "M04").row
    assert row["reference_model"] is True and row["verdict"] == "not_judged"
    assert not row["alarm"] and row["fault"] is None
    row = judge_log(data, str(LOG), None, REFERENCE_MACHINE).row
    assert row["reference_model"] is False and row["verdict"] == "fault"


def test_a_reload_that_declares_another_machine_withholds_from_then_on(tmp_path: Path) -> None:
    """SIGHUP after `machine_id` changed: the same model file, but a new ticker that
    withholds (and back again when the machine is the model's)."""
    from monitor.codec.frames import FrameCodec
    from monitor.config.layout import row_layout
    from monitor.live.loops import Loop
    from monitor.live.reload import prepare

    p = tmp_path / "m.yaml"
    p.write_text("machine_id: reference\n")
    cfg = load_config(p)
    codec = FrameCodec.from_dbc(cfg.dbc)
    _, views = row_layout(cfg, codec)
    lp = Loop(cfg.monitored_loops[0], cfg, codec, views[0])
    assert lp.ticker.reference is None
    p.write_text("machine_id: EX-0042\n")
    result = prepare(cfg, [lp], None)  # type: ignore[arg-type]  # no event log change
    assert not isinstance(result, Exception) and result.loaded[0] is not None
    _, ticker, _ = result.loaded[0]
    assert ticker.reference is not None and "'EX-0042'" in ticker.reference
