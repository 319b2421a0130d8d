"""Twin runs of `monitor eval-sim` (noise-free, with and without the fault) and the
"exercised" counts.

Expected values come from the simulator's definitions, not from running it: the kernel
clips the spool position at the stroke limit (1 - 0.6 severity) and otherwise uses the
command as it is (no spool dynamics in the reference machine), and every fault input is
zero before its onset, so a fault that never acts leaves the plant bit for bit unchanged.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from monitor.cli import main
from monitor.evaluation.exercised import exercised_cell, exercised_markdown
from monitor.evaluation.twins import fault_view, predictor_view, simulate_twins, twin_residual
from monitor.io.recording import Recording
from monitor.model.modelfile import MonitorModel, load_model
from monitor.resources import resource_path
from monitor.signals import FAULT_NAMES
from monitor.sim.cycles import make_cycle
from monitor.sim.faults import Fault
from monitor.sim.machine import load_machine
from monitor.sim.simulate import simulate


@pytest.fixture(scope="module")
def model() -> MonitorModel:
    return load_model(resource_path("config", "boom_default.model.npz"))


def _commands(phases: list[tuple[float, float]], total_s: float) -> Recording:
    """100 Hz commands: SpoolCmd from (start_s, level %) steps, the boom cycle's pump,
    engine and oil temperature."""
    t = np.arange(int(round(total_s * 100)) + 1) * 0.01
    spool = np.zeros_like(t)
    for start, level in phases:
        spool[t >= start - 1e-9] = level
    cols = {
        "SpoolCmd": spool,
        "PumpDispCmd": np.full_like(t, 100.0),
        "EngineSpeed": np.full_like(t, 2200.0),
        "OilTemp": np.full_like(t, 50.0),
    }
    return Recording(t, cols, source="hand-built commands")


def test_noisy_twin_is_the_simulated_run() -> None:
    """The recording the detector scores is exactly simulate(..., seed) of the run."""
    commands = make_cycle("boom", 40.0, 123)
    faults = [Fault("piston_wear", 0.5, 10.0)]
    twins = simulate_twins(commands, load_machine(), faults, seed=123)
    direct = simulate(commands, load_machine(), faults, seed=123)
    assert set(twins.noisy.columns) == set(direct.columns)
    for name in direct.columns:
        assert np.array_equal(twins.noisy[name], direct[name], equal_nan=True), name
    clean = simulate(commands, load_machine(), faults, seed=None)
    assert np.array_equal(twins.faulty["PP"], clean["PP"])


@pytest.mark.parametrize("name", FAULT_NAMES)
def test_severity_zero_changes_nothing(model: MonitorModel, name: str) -> None:
    twins = simulate_twins(make_cycle("boom", 45.0, 7), load_machine(), [Fault(name, 0.0, 5.0)], 7)
    assert np.all(twin_residual(model, twins) == 0.0)
    view = fault_view(model, twins, 5.0)
    assert view["fault_j_ratio"] == 0.0 and view["fault_j_above_eps0_s"] == 0.0
    assert view["fault_signal_share"] is None and view["fault_regime_share"] is None
    # The same inputs give the predictor the same predictions: no residual change either.
    passed = predictor_view(model, twins, 5.0, np.ones(len(twins.faulty), dtype=bool))
    assert passed["fault_residual_j_ratio"] == 0.0
    assert passed["fault_residual_level_ratio"] == 0.0


@pytest.mark.parametrize("name", FAULT_NAMES)
def test_nothing_before_the_onset(model: MonitorModel, name: str) -> None:
    onset = 20.0
    commands = make_cycle("boom", 45.0, 8)
    twins = simulate_twins(commands, load_machine(), [Fault(name, 1.0, onset)], 8)
    e = twin_residual(model, twins)
    before = twins.faulty.t - twins.faulty.t[0] < onset - 1e-9
    assert np.all(e[before] == 0.0)
    assert np.any(e[~before] != 0.0)  # full severity over a boom cycle does act


# Raise at 30 % (about 0.11 m/s for 3 s from the rod's 0.1 m: off the top stop), hold, then
# lower; the J window (N + 1 = 30 s) ending at 40 s holds every move.
RAISE = [(1.0, 30.0), (4.0, 0.0)]


def test_stroke_limit_never_reached_gives_ratio_zero(model: MonitorModel) -> None:
    """Severity 0.5 limits the spool to 70 %; a lever within +-30 % never meets the clip."""
    commands = _commands([*RAISE, (6.0, -30.0), (8.0, 0.0)], 40.0)
    twins = simulate_twins(commands, load_machine(), [Fault("spool_stroke", 0.5, 0.5)], None)
    assert np.all(twin_residual(model, twins) == 0.0)
    assert fault_view(model, twins, 0.5)["fault_j_ratio"] == 0.0
    judged = np.ones(len(twins.faulty), dtype=bool)
    assert predictor_view(model, twins, 0.5, judged)["fault_residual_level_ratio"] == 0.0


def test_full_lowering_past_the_limit_gives_ratio_above_zero(model: MonitorModel) -> None:
    """Severity 1 limits the spool to 40 %, below the ~55 % where lowering stops being
    pump-limited (monitor.sim.cycles): a 100 % lowering meets the clip, the orifices are
    smaller and the rod comes down slower.  Nothing differs before the lowering starts."""
    commands = _commands([*RAISE, (6.0, -100.0), (7.5, 0.0)], 40.0)
    twins = simulate_twins(commands, load_machine(), [Fault("spool_stroke", 1.0, 0.5)], None)
    e = twin_residual(model, twins)
    t = twins.faulty.t
    assert np.all(e[t < 6.0 - 1e-9] == 0.0)
    assert np.any(e[(t >= 6.0) & (t < 7.5)] != 0.0)
    lowered = lambda rec: rec["RodPosTrue"][t == 4.0][0] - rec["RodPosTrue"][-1]  # noqa: E731
    assert 0.0 < lowered(twins.faulty) < lowered(twins.healthy)
    view = fault_view(model, twins, 0.5)
    assert view["fault_j_ratio"] > 0.0
    passed = predictor_view(model, twins, 0.5, np.ones(len(t), dtype=bool))
    assert passed["fault_residual_j_ratio"] > 0.0
    assert passed["fault_residual_level_ratio"] >= passed["fault_residual_j_ratio"]


def test_unjudged_samples_pause_the_window(model: MonitorModel) -> None:
    """Samples the detector did not judge do not count: with none judged, no J at all."""
    commands = _commands([*RAISE, (6.0, -100.0), (7.5, 0.0)], 40.0)
    twins = simulate_twins(commands, load_machine(), [Fault("spool_stroke", 1.0, 0.5)], None)
    view = fault_view(model, twins, 0.5, judged=np.zeros(len(twins.faulty), dtype=bool))
    assert view["fault_j_ratio"] is None


def _run(ratio: float, detected: bool) -> dict:
    return {
        "fault": "spool_stroke",
        "severity": 0.3,
        "onset": "abrupt",
        "detected": detected,
        "fault_j_ratio": ratio,
    }


def test_exercised_counts_on_hand_made_runs() -> None:
    runs = [
        _run(2.0, True),  # exercised, found
        _run(1.0, False),  # exactly at eps0 counts as exercised; missed
        _run(0.5, True),  # found (by B, say) though the fault alone kept J below eps0
        _run(0.2, False),  # neither
        _run(0.0, False),  # the fault changed nothing
    ]
    c = exercised_cell(runs)
    assert c["exercised"] == 2 and c["detected_exercised"] == 1
    assert c["detection_rate_exercised"] == 0.5
    assert c["detected_not_exercised"] == 1 and c["detection_rate_not_exercised"] == 1 / 3
    row = {"fault": "spool_stroke", "severity": 0.3, "all": {"runs": 5, "detected": 2, **c}}
    text = "\n".join(exercised_markdown([row]))
    assert "| spool_stroke | 0.3 | 2/5 | 2 | 1/2 | 1/3 |" in text
    none = exercised_cell([_run(0.5, False)])
    assert none["exercised"] == 0 and none["detection_rate_exercised"] is None


def test_passed_columns_when_the_residual_view_is_there() -> None:
    runs = [
        {**_run(0.5, True), "fault_residual_level_ratio": 1.5},
        {**_run(0.5, False), "fault_residual_level_ratio": 0.5},
    ]
    c = exercised_cell(runs)
    assert c["exercised"] == 0 and c["passed"] == 1 and c["detected_passed"] == 1
    row = {"fault": "piston_wear", "severity": 0.1, "all": {"runs": 2, "detected": 1, **c}}
    text = "\n".join(exercised_markdown([row]))
    assert "| piston_wear | 0.1 | 1/2 | 0 | - | 1/2 | 1 | 1/1 | 0/1 |" in text


def test_no_twins_no_counts() -> None:
    runs = [{"fault": "spool_stroke", "severity": 0.3, "detected": True}]
    assert exercised_cell(runs) == {}
    assert exercised_markdown([{"fault": "x", "severity": 0.3, "all": {"runs": 1}}]) == []


def test_cli_twins_and_no_twins(tmp_path: Path) -> None:
    common = [
        "eval-sim",
        "--model",
        "shipped",
        "--faults",
        "spool_stroke",
        "--severities",
        "1.0",
        "--runs",
        "1",
        "--onsets",
        "abrupt",
        "--normal-hours",
        "0",
    ]
    on, off, md = tmp_path / "on.json", tmp_path / "off.json", tmp_path / "on.md"
    assert main([*common, "--json", str(on), "--markdown", str(md)]) == 0
    assert main([*common, "--no-twins", "--json", str(off)]) == 0
    a, b = (json.loads(p.read_text()) for p in (on, off))
    ra, rb = a["models"]["shipped"]["runs"]["fault"], b["models"]["shipped"]["runs"]["fault"]
    assert [r["fault"] for r in ra] == ["spool_stroke"]
    assert ra[0]["fault_j_ratio"] >= 0.0 and "fault_j_ratio" not in rb[0]
    # The twins do not change what the detector scored.
    assert {k: v for k, v in ra[0].items() if not k.startswith("fault_")} == {
        k: v for k, v in rb[0].items() if not k.startswith("fault_")
    }
    assert "--no-twins" in b["rerun"] and "--faults spool_stroke" in a["rerun"]
    assert "Could a detector see it" in md.read_text()


def test_cli_twin_residuals_need_the_twins(tmp_path: Path) -> None:
    argv = [
        "eval-sim",
        "--model",
        "shipped",
        "--no-twins",
        "--twin-residuals",
        "--json",
        str(tmp_path / "x.json"),
    ]
    assert main(argv) == 2
