"""``monitor eval-uci``: rig-folder loader errors, a synthetic rig with known answers, the real
rig's JSON keys (skipped without ../shared) and user errors."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from monitor.cli import main
from monitor.errors import InputFileError
from monitor.evaluation.uci import sensors_needed
from monitor.evaluation.uci_data import load_rig
from monitor.evaluation.uci_presets import DETECTION_KEYS, UCI_PRESETS

UCI_DIR = Path(__file__).resolve().parents[2] / "shared" / "data" / "uci-hydraulic-1hz"
SENSORS = sensors_needed(tuple(UCI_PRESETS))


def _profile_rows() -> list[tuple[int, int, int, int, int]]:
    """(cooler, valve, pump_leak, accumulator, stable) per synthetic cycle 0..47."""
    rows = [(100, 100, 0, 130, 0)] * 16  # healthy
    rows += [(100, 100, 2, 130, 0)] * 8  # pump_leak=2: PS2 +20 bar
    rows += [(100, 100, 0, 115, 0)] * 8  # accumulator=115: labelled, but no signal change
    rows += [(100, 73, 0, 130, 1)] * 8  # valve=73: FS1 -3 L/min in the loaded phases
    rows += [(20, 100, 0, 130, 0)] * 8  # healthy with the cooler at 20 %: warmer oil only
    return rows


def write_rig(folder: Path, seed: int = 0) -> list[tuple[int, int, int, int, int]]:
    """A small rig folder: a 60 s step profile with sensor noise and known faults."""
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    rows = _profile_rows()
    n = len(rows)
    step = np.repeat([4.0, 0.0, 1.0, 2.0, 1.0, 0.5], 10)  # six 10 s load phases
    sig = {name: np.empty((n, 60)) for name in SENSORS}
    for i, (cooler, valve, leak, _acc, _st) in enumerate(rows):
        ps1 = 150 + 10 * step + rng.normal(0, 0.1, 60)
        ps2 = ps1 - 30 + rng.normal(0, 0.1, 60) + (20.0 if leak == 2 else 0.0)
        fs1 = np.where(step > 0, 8.0, 0.5) + rng.normal(0, 0.02, 60)
        if valve == 73:
            fs1 = fs1 - 3.0 * (step > 0)
        sig["PS1"][i], sig["PS2"][i], sig["FS1"][i] = ps1, ps2, fs1
        sig["PS3"][i] = 2 + rng.normal(0, 0.02, 60)
        sig["EPS1"][i] = 2300 + 5 * ps1 + rng.normal(0, 2, 60)
        sig["TS1"][i] = (45.0 if cooler == 100 else 55.0) + rng.normal(0, 0.05, 60)
    for name, m in sig.items():
        np.savetxt(folder / f"{name}.txt", m, fmt="%.3f", delimiter="\t")
    np.savetxt(folder / "profile.txt", np.array(rows), fmt="%d", delimiter="\t")
    np.savetxt(folder / "cycles.txt", np.arange(n), fmt="%d")
    return rows


# --------------------------------------------------------------------------- loader errors


def test_loader_reads_a_rig_folder(tmp_path) -> None:
    rows = write_rig(tmp_path / "rig")
    rc = load_rig(tmp_path / "rig", ["PS1", "FS1"])
    assert len(rc) == len(rows) and rc.signals["PS1"].shape == (len(rows), 60)
    assert rc.cycle_id_source == "cycles.txt"
    assert rc.healthy.sum() == 24 and rc.profile["valve"][35] == 73
    (tmp_path / "rig" / "cycles.txt").unlink()
    assert load_rig(tmp_path / "rig", ["PS1"]).cycle_id_source == "row order"


def _corrupt(path: Path, line: int, fn) -> None:
    lines = path.read_text().splitlines()
    lines[line - 1] = fn(lines[line - 1])
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize(
    ("file", "edit", "expected"),
    [
        ("PS2.txt", None, "PS2.txt: file not found"),
        ("PS2.txt", (3, lambda s: s.rsplit("\t", 1)[0]), "PS2.txt:3: 59 tab-separated columns"),
        ("FS1.txt", (2, lambda s: "abc\t" + s.split("\t", 1)[1]), "FS1.txt:2: column 1: 'abc'"),
        (
            "EPS1.txt",
            (5, lambda s: s.replace("\t", "\tnan\t", 1).rsplit("\t", 1)[0]),
            "EPS1.txt:5: column 2: value is not finite",
        ),
        ("profile.txt", (7, lambda s: "50" + s[3:]), "profile.txt:7: column 1 (cooler) is 50"),
        ("cycles.txt", (4, lambda s: "1.5"), "cycles.txt:4: cycle number must be an integer"),
    ],
)
def test_loader_errors_name_file_and_line(tmp_path, file, edit, expected) -> None:
    write_rig(tmp_path / "rig")
    path = tmp_path / "rig" / file
    if edit is None:
        path.unlink()
    else:
        _corrupt(path, *edit)
    with pytest.raises(InputFileError, match=expected.replace("(", r"\(").replace(")", r"\)")):
        load_rig(tmp_path / "rig", SENSORS)


def test_loader_rejects_row_counts_that_disagree(tmp_path) -> None:
    write_rig(tmp_path / "rig")
    path = tmp_path / "rig" / "TS1.txt"
    path.write_text("".join(path.read_text().splitlines(keepends=True)[:-2]))
    with pytest.raises(InputFileError, match=r"TS1.txt:47: 46 cycles .* profile.txt has 48"):
        load_rig(tmp_path / "rig", SENSORS)


def test_loader_rejects_an_empty_file_and_a_missing_folder(tmp_path) -> None:
    write_rig(tmp_path / "rig")
    (tmp_path / "rig" / "PS1.txt").write_text("\n")
    with pytest.raises(InputFileError, match="PS1.txt: empty file"):
        load_rig(tmp_path / "rig", SENSORS)
    with pytest.raises(InputFileError, match="not a folder"):
        load_rig(tmp_path / "nowhere", SENSORS)


# --------------------------------------------------------------------------- synthetic rig


def test_synthetic_rig_rates_known_by_construction(tmp_path, capsys) -> None:
    rig = tmp_path / "rig"
    write_rig(rig)
    out = tmp_path / "uci.json"
    assert main(["eval-uci", "--train", str(rig), "--test", str(rig), "--json", str(out)]) == 0
    res = json.loads(out.read_text())
    # Same folder: even cycle numbers train, odd ones are scored (24 of 48).
    assert res["split"]["same_folder"] and res["split"]["test_cycles"] == 24
    assert res["split"]["train_cycles"] == 24
    assert res["split"]["pattern_cycles"] + res["split"]["j0_cycles"] == 12
    det = res["detection"]
    assert set(det) == {f"{c}={v}" for c, v in DETECTION_KEYS}
    assert res["healthy_false_alarm_rate"] == 0.0  # 8 + 4 healthy test cycles, none alarmed
    assert det["pump_leak=2"] == 1.0  # PS2 20 bar high
    assert det["valve=73"] == 1.0  # FS1 3 L/min low
    assert det["accumulator=115"] == 0.0  # a label with no change in any signal
    assert det["cooler=20"] == 0.0  # the cooler at 20 % is healthy and was trained on
    assert det["pump_leak=1"] is None and det["cooler=3"] is None  # no such test cycles
    assert res["default_preset"] in UCI_PRESETS
    assert res["model"]["eps0"] == pytest.approx(2 * res["model"]["J0"])
    captured = capsys.readouterr()
    assert "pump_leak=2" in captured.out and "eval-uci: loaded" in captured.err


def test_separate_folders_drop_test_cycles_that_were_trained_on(tmp_path) -> None:
    write_rig(tmp_path / "a", seed=1)
    shutil.copytree(tmp_path / "a", tmp_path / "b")
    out = tmp_path / "uci.json"
    args = [
        "eval-uci",
        "--train",
        str(tmp_path / "a"),
        "--test",
        str(tmp_path / "b"),
        "--json",
        str(out),
        "--preset",
        "rig",
        "--window",
        "9",
    ]
    assert main(args) == 0
    res = json.loads(out.read_text())
    assert res["split"]["test_cycles_dropped_as_also_in_train"] == 48
    assert res["split"]["test_cycles"] == 0
    assert res["healthy_false_alarm_rate"] is None


# --------------------------------------------------------------------------- user errors


def test_missing_folder_exits_2_with_one_line(tmp_path, capsys) -> None:
    args = [
        "eval-uci",
        "--train",
        str(tmp_path / "none"),
        "--test",
        str(tmp_path / "none"),
        "--json",
        str(tmp_path / "x.json"),
    ]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("monitor eval-uci: error:") and "none" in err[0]
    assert not (tmp_path / "x.json").exists()


def test_malformed_file_and_no_healthy_cycles_exit_2(tmp_path, capsys) -> None:
    rig = tmp_path / "rig"
    write_rig(rig)
    _corrupt(rig / "PS3.txt", 10, lambda s: s + "\t1.0")
    args = ["eval-uci", "--train", str(rig), "--test", str(rig), "--json", str(tmp_path / "x")]
    assert main(args) == 2
    assert "PS3.txt:10: 61 tab-separated columns" in capsys.readouterr().err
    write_rig(rig)
    prof = np.loadtxt(rig / "profile.txt", dtype=int)
    prof[:, 3] = 90  # every accumulator at 90 bar: no healthy cycle left
    np.savetxt(rig / "profile.txt", prof, fmt="%d", delimiter="\t")
    assert main(args) == 2
    assert "0 healthy cycles" in capsys.readouterr().err


# --------------------------------------------------------------------------- real rig


@pytest.mark.skipif(not UCI_DIR.is_dir(), reason=f"real rig data not present at {UCI_DIR}")
def test_real_rig_json_keys(tmp_path) -> None:
    out = tmp_path / "uci.json"
    args = [
        "eval-uci",
        "--train",
        str(UCI_DIR),
        "--test",
        str(UCI_DIR),
        "--json",
        str(out),
        "--max-cycles",
        "300",
        "--window",
        "19",
    ]
    assert main(args) == 0
    res = json.loads(out.read_text())
    assert set(res["detection"]) == {f"{c}={v}" for c, v in DETECTION_KEYS}
    assert all(v is None or 0.0 <= v <= 1.0 for v in res["detection"].values())
    assert 0.0 <= res["healthy_false_alarm_rate"] <= 1.0
    assert set(res["presets"]) == set(UCI_PRESETS)
    assert res["split"]["test_cycles"] == 300
    assert res["model"]["roles"] == {"PP": "PS1", "QP": "FS1", "PA": "PS2", "PB": "PS3"}
