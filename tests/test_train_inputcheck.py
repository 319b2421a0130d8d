"""`monitor train` checks its input before fitting: a recording the reference model calls
faulty is named with the fault (and, with --fault-check refuse, refused before fitting); an
oil-temperature span too narrow for the logs the model will judge is warned about."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from monitor.cli import main
from monitor.config.settings import load_config
from monitor.io.csvio import write_csv
from monitor.io.recording import Recording
from monitor.sim.cycles import make_cycle
from monitor.sim.faults import parse_fault
from monitor.sim.machine import load_machine
from monitor.sim.simulate import simulate
from monitor.training.inputcheck import envelope_warnings

CFG = load_config()
QUICK = ["--isolation", "none"]  # no fault signatures: the check comes before them anyway


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    """What `monitor simulate --duration 150 --seed 3 --fault piston_wear:0.5@0` and a
    normal run (seed 4) write."""
    tmp = tmp_path_factory.mktemp("train_input")
    out = {}
    for name, seed, faults in (
        ("piston", 3, [parse_fault("piston_wear:0.5@0")]),
        ("normal", 4, []),
    ):
        rec = simulate(make_cycle("boom", 150.0, seed), load_machine(), faults=faults, seed=seed)
        out[name] = tmp / f"{name}.csv"
        write_csv(out[name], rec)
    return out


def test_a_recording_with_piston_wear_is_named_with_the_fault(runs, tmp_path, capsys) -> None:
    model = tmp_path / "m.npz"
    rc = main(["train", str(runs["piston"]), "--out", str(model), *QUICK])
    err = capsys.readouterr().err
    assert rc == 0 and model.exists()
    assert f"warning: {runs['piston']} looks like piston_wear (the reference model " in err
    assert err.index("looks like piston_wear") < err.index("fitting")  # said before fitting


def test_fault_check_refuse_stops_before_fitting(runs, tmp_path, capsys) -> None:
    model = tmp_path / "m.npz"
    rc = main(
        ["train", str(runs["piston"]), "--out", str(model), "--fault-check", "refuse", *QUICK]
    )
    err = capsys.readouterr().err
    assert rc == 2
    assert f"{runs['piston']} looks like piston_wear" in err
    assert "--fault-check warn" in err  # how to train on it anyway
    assert "fitting" not in err and not model.exists()
    # The same option on a normal recording trains.
    rc = main(
        ["train", str(runs["normal"]), "--out", str(model), "--fault-check", "refuse", *QUICK]
    )
    assert rc == 0 and model.exists()


def test_a_normal_recording_is_not_flagged(runs, tmp_path, capsys) -> None:
    model = tmp_path / "m.npz"
    rc = main(["train", str(runs["normal"]), "--out", str(model), *QUICK])
    err = capsys.readouterr().err
    assert rc == 0 and model.exists()
    assert "checking 1 recording(s) against the reference model" in err
    assert "looks like" not in err
    # One simulated run holds one oil temperature: the narrow envelope is named.
    assert "warning: OilTemp spans " in err and "will be not judged" in err


def _oil(values: np.ndarray) -> Recording:
    t = np.arange(len(values)) * 0.01
    return Recording(t, {"OilTemp": values}, "oil")


def test_envelope_warning_names_the_signal_and_ranges() -> None:
    one = [_oil(np.linspace(40.1, 41.0, 500)), _oil(np.full(300, 40.5))]
    # The margin: 5 % of the 0.9 degC span is below the 5 degC floor (validity.margin_c).
    assert envelope_warnings(one, CFG.gating) == [
        "OilTemp spans 40.1-41.0 degC only; logs outside 35.1-46.0 degC (the trained range "
        "and its margin) will be not judged: train on data across the oil temperatures the "
        "machine works at (at least 10 degC apart)"
    ]
    # Two days at 38 and 55 degC: wide enough.
    assert envelope_warnings([_oil(np.full(100, 38.0)), _oil(np.full(100, 55.0))], CFG.gating) == []
    # A cold start from 10 degC does not widen it: below the warm-up line nothing is judged.
    cold = _oil(np.concatenate([np.linspace(10.0, 29.0, 500), np.full(500, 40.5)]))
    assert envelope_warnings([cold], CFG.gating)[0].startswith("OilTemp spans 40.5-40.5 degC only")
    assert envelope_warnings([_oil(np.full(10, np.nan))], CFG.gating) == []
