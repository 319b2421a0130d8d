"""One loop of a whole-machine recording (``--loop``): the loop's signals under the contract
names and the other loops' spool commands as ``SpoolCmd@LOOP``, the same from a candump log
through dbc/excavator4.dbc and from a CSV whose columns are the DBC's names; the ``section``
model of a load-sensing loop reads PP and its neighbours' demand as inputs."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from monitor.cli import main
from monitor.codec.frames import FrameCodec
from monitor.config.layout import row_layout
from monitor.config.settings import load_config
from monitor.detection.offline import detect
from monitor.detection.plausibility import COLUMNS, Plausibility, PlausibilityConfig, finding
from monitor.io.csvio import read_csv
from monitor.model.modelfile import load_model
from monitor.model.spec import DGRNNSpec
from monitor.offline.recordings import read_loop
from monitor.resources import resource_path

CONFIG = resource_path("config", "excavator4.yaml")
#: Each loop's DBC prefix on dbc/excavator4.dbc (the boom's frames are unprefixed).
PREFIX = {"boom": "", "stick": "Stick_", "bucket": "Bucket_", "swing": "Swing_"}


@pytest.fixture(scope="module")
def whole(tmp_path_factory) -> dict[str, Path]:
    """20 s of truck loading as a CSV and as a candump log (same seed: same signals)."""
    d = tmp_path_factory.mktemp("whole")
    args = ["simulate", "--machine", "excavator4", "--duration", "20", "--seed", "8"]
    args += ["--cycle", "truck-loading"]
    out = {"csv": d / "whole.csv", "log": d / "whole.log"}
    for path in out.values():
        assert main([*args, "--out", str(path)]) == 0
    return out


def test_every_loop_sees_the_others_spool_commands_by_loop_name() -> None:
    cfg = load_config(CONFIG)
    columns, views = row_layout(cfg, FrameCodec.from_dbc(cfg.dbc))
    for loop, view in zip(("boom", "stick", "bucket", "swing"), views, strict=True):
        named = dict(zip(view, columns, strict=True))
        others = {n for n in view if "@" in n}
        assert others == {f"SpoolCmd@{o}" for o in PREFIX if o != loop}
        for o in PREFIX:
            if o != loop:
                assert named[f"SpoolCmd@{o}"] == PREFIX[o] + "SpoolCmd"
        assert named["SpoolCmd"] == PREFIX[loop] + "SpoolCmd"


def test_a_csv_with_the_dbc_names_gives_the_loop_as_the_log_does(whole) -> None:
    cfg = load_config(CONFIG)
    wide = read_csv(whole["csv"], required=("t",))
    from_csv = read_loop(whole["csv"], cfg, "stick")
    from_log = read_loop(whole["log"], cfg, "stick")
    for contract in ("PP", "PA", "PB", "QP", "SpoolCmd", "RodPos"):
        np.testing.assert_array_equal(from_csv[contract], wide["Stick_" + contract])
    np.testing.assert_array_equal(from_csv["SpoolCmd@boom"], wide["SpoolCmd"])
    np.testing.assert_array_equal(from_csv["SpoolCmd@swing"], wide["Swing_SpoolCmd"])
    # The log: the same values through the DBC (0.01 resolution), on the sampler's clock
    # (its first row is the first full one): compare the rows at the same times.
    k = np.searchsorted(np.round(from_csv.t, 6), np.round(from_log.t - from_log.t[0], 6))
    assert len(from_log) > 1800 and k[-1] < len(from_csv)
    for name in ("PA", "QP", "RodPos", "SpoolCmd@bucket"):
        np.testing.assert_allclose(from_log[name], from_csv[name][k], atol=0.0051)
    assert not read_loop(whole["csv"], cfg, "swing").has("RodPos")


def test_a_csv_without_the_loops_own_column_is_refused_naming_it(whole, tmp_path, capsys):
    lines = whole["csv"].read_text().splitlines()
    header = lines[0].split(",")
    drop = header.index("Stick_QP")
    cut = [",".join(f for i, f in enumerate(ln.split(",")) if i != drop) for ln in lines[:50]]
    path = tmp_path / "no_stick_qp.csv"
    path.write_text("\n".join(cut) + "\n")
    capsys.readouterr()
    assert main(["detect", str(path), "--loop", "stick", "--config", str(CONFIG)]) == 2
    err = capsys.readouterr().err
    assert "no_stick_qp.csv" in err and "Stick_QP" in err and "Traceback" not in err
    # The boom's signals are all there: its loop reads the same file.
    rec = read_loop(path, load_config(CONFIG), "boom")
    assert rec.has("QP") and rec.has("SpoolCmd@stick")


def test_the_section_preset_takes_pp_and_the_neighbours_as_inputs() -> None:
    spec = DGRNNSpec.preset("section", neighbours=("SpoolCmd@boom", "SpoolCmd@swing"))
    assert spec.outputs == ("PA", "PB", "QP")
    assert "PP" in spec.exogenous and ("PP", 0) in spec.features
    assert ("SpoolCmd@boom", 0) in spec.features and ("SpoolCmd@swing", 0) in spec.features
    assert DGRNNSpec.from_dict(spec.to_dict()) == spec


def test_train_and_detect_a_loop_of_a_whole_machine_csv(whole, tmp_path, capsys) -> None:
    model = tmp_path / "stick.model.npz"
    argv = ["train", str(whole["csv"]), "--loop", "stick", "--config", str(CONFIG)]
    argv += ["--fault-check", "off", "--max-patterns", "300", "--out", str(model)]
    argv += ["--validation-fraction", "0.5", "--window", "300"]
    assert main(argv) == 0
    m = load_model(model)
    # A loop of a load-sensing machine (config/excavator4.yaml): the section preset with
    # the three other loops' commands, and no boom-simulator signatures.
    assert m.spec.outputs == ("PA", "PB", "QP")
    assert {v for v in m.spec.exogenous if "@" in v} == {
        "SpoolCmd@boom",
        "SpoolCmd@bucket",
        "SpoolCmd@swing",
    }
    assert m.card.loop == "stick"
    summary = tmp_path / "s.json"
    argv = ["detect", str(whole["log"]), "--loop", "stick", "--config", str(CONFIG)]
    assert main([*argv, "--model", str(model), "--summary", str(summary)]) == 0
    s = json.loads(summary.read_text())
    assert s["loop"] == "stick" and s["judged_s"] > 0
    # Another loop's model for the stick is refused before the recording is read.
    capsys.readouterr()
    boom = ["detect", str(whole["log"]), "--loop", "boom", "--config", str(CONFIG)]
    assert main([*boom, "--model", str(model)]) == 2
    assert "stick" in capsys.readouterr().err


def test_isolation_from_the_boom_simulator_is_refused_for_a_section_model(whole, tmp_path):
    argv = ["train", str(whole["csv"]), "--loop", "stick", "--config", str(CONFIG)]
    argv += ["--isolation", "sim", "--out", str(tmp_path / "m.npz")]
    assert main(argv) == 2
    assert not (tmp_path / "m.npz").exists()


def test_the_shipped_models_are_section_models_of_their_own_loops() -> None:
    cfg = load_config(CONFIG)
    for lc in cfg.monitored_loops:
        m = load_model(lc.model)
        assert lc.model.name == f"{lc.name}_excavator4.model.npz"
        assert m.card.loop == lc.name
        # The bucket's model predicts its rod's speed too (`monitor train --rod-speed`).
        rod = ("RodSpeed",) if lc.name == "bucket" else ()
        assert m.spec.outputs == ("PA", "PB", "QP", *rod) and "PP" in m.spec.exogenous
        others = {f"SpoolCmd@{o}" for o in PREFIX if o != lc.name}
        assert {v for v in m.spec.exogenous if "@" in v} == others


@pytest.fixture(scope="module")
def stick_fault(tmp_path_factory) -> Path:
    """A stick with worn metering edges (spool_wear 0.5 from 120 s) in 300 s of mixed work,
    on a seed the shipped models were not trained or thresholded on."""
    path = tmp_path_factory.mktemp("stick") / "stick_spool_wear.csv"
    argv = ["simulate", "--machine", "excavator4", "--duration", "300", "--seed", "77"]
    assert main([*argv, "--fault", "stick.spool_wear:0.5@120", "--out", str(path)]) == 0
    return path


def test_a_stick_fault_raises_the_stick_alarm_and_not_the_booms(stick_fault) -> None:
    cfg = load_config(CONFIG)
    said = {}
    for lc in cfg.monitored_loops:
        rec = read_loop(stick_fault, cfg, lc.name)
        said[lc.name] = detect(load_model(lc.model), rec, cfg.alarm, gating=cfg.gating).summary
    assert said["stick"]["alarm"] and said["stick"]["first_alarm_t"] > 120.0
    assert not said["boom"]["alarm"]
    assert all(s["sensor_checks"] == [] for s in said.values())


def _findings(rec, cfg: PlausibilityConfig) -> set[tuple]:
    x = np.column_stack([rec[c] for c in COLUMNS])
    check, sig = Plausibility(cfg, load_config(CONFIG).alarm.min_engine_rpm).series(x)
    return {finding(int(c), int(s)) for c, s in zip(check, sig, strict=True) if c}


def test_healthy_whole_machine_work_is_a_sensor_fault_only_under_single_loop_rules(stick_fault):
    # The boom lowers (the pump feeds B at a few bar plus the margin) with its load on A:
    # the single loop's rule reads A above the pump as an offset; the load-sensing rule
    # of config/excavator4.yaml judges the fed port only, and finds nothing on any loop.
    cfg = load_config(CONFIG)
    boom = read_loop(stick_fault, cfg, "boom")
    assert ("PA", "pump_below_port") in _findings(boom, PlausibilityConfig())
    for lc in cfg.monitored_loops:
        rec = read_loop(stick_fault, cfg, lc.name)
        assert _findings(rec, cfg.gating.plausibility) == set(), lc.name


def test_detect_without_loop_asks_for_one_on_a_section_model(whole, capsys) -> None:
    capsys.readouterr()
    assert main(["detect", str(whole["csv"]), "--config", str(CONFIG)]) == 2
    err = capsys.readouterr().err
    assert "give --loop NAME (boom, stick, bucket, swing)" in err and "Traceback" not in err


def test_the_daemon_reads_each_loop_as_detect_loop_does(tmp_path) -> None:
    # One mapping for the daemon and `detect --loop`: a whole-machine log through the
    # shipped four-loop config on a virtual bus gives, per loop, detect's events.
    from live_support import assert_same_events, live_config, replay_settled, run_daemon

    log = tmp_path / "whole.log"
    argv = ["simulate", "--machine", "excavator4", "--duration", "90", "--seed", "78"]
    assert main([*argv, "--out", str(log)]) == 0
    cfg = live_config(tmp_path, CONFIG)
    _, events, _, _ = run_daemon(cfg, replay_settled(log))
    for lc in cfg.loops:
        live = [e for e in events if e.get("loop") == lc.name]
        rec = read_loop(log, cfg, lc.name)
        offline = detect(load_model(lc.model), rec, cfg.alarm, cfg.horizon, gating=cfg.gating)
        assert live and offline.events
        assert_same_events(live, offline)
        assert all(e["state"] != "sensor_fault" for e in live), lc.name
