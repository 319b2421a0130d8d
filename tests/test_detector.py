"""Model files, ``monitor train`` and ``monitor detect`` on simulated recordings."""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest

from monitor.cli import main
from monitor.detection.offline import detect
from monitor.errors import InputFileError, ModelFileError
from monitor.io.csvio import read_csv, write_csv
from monitor.io.recording import Recording
from monitor.model.modelfile import load_model, save_model
from monitor.resources import resource_path
from monitor.sim.cycles import make_cycle
from monitor.sim.faults import Fault
from monitor.sim.machine import load_machine
from monitor.sim.simulate import simulate
from monitor.training.settings import (
    DGRNNSettings,
    IsolationSettings,
    StatisticSettings,
    TrainConfig,
)
from monitor.training.train import train

MACHINE = load_machine()


@pytest.fixture(scope="module")
def small_model():
    recs = [simulate(make_cycle("boom", 120, s), MACHINE, seed=s) for s in (11, 12, 13)]
    cfg = TrainConfig(
        DGRNNSettings(max_patterns=400),
        statistics=StatisticSettings(window_n=300),
        isolation=IsolationSettings("none"),
    )
    return train(recs, cfg)


def test_model_file_round_trip_is_bit_identical(tmp_path, small_model):
    path = tmp_path / "m.npz"
    save_model(path, small_model)
    back = load_model(path)
    assert back.header() == small_model.header()
    assert np.array_equal(back.dgrnn.grnn.patterns_, small_model.dgrnn.grnn.patterns_)
    rec = simulate(make_cycle("boom", 30, 99), MACHINE, seed=99)
    a, b = detect(small_model, rec), detect(back, rec)
    assert np.array_equal(a.j, b.j, equal_nan=True)
    assert a.events == b.events


def test_corrupt_old_and_foreign_model_files_are_refused(tmp_path, small_model):
    path = tmp_path / "m.npz"
    save_model(path, small_model)
    raw = bytearray(path.read_bytes())
    # Flip one byte inside the stored patterns (the header stays parseable).
    raw[len(raw) // 2] ^= 0xFF
    bad = tmp_path / "corrupt.npz"
    bad.write_bytes(bytes(raw))
    with pytest.raises(ModelFileError, match="corrupt|not a monitor model"):
        load_model(bad)
    text = tmp_path / "text.npz"
    text.write_text("hello")
    with pytest.raises(ModelFileError, match="not a monitor model file"):
        load_model(text)
    with pytest.raises(ModelFileError, match="no such model file"):
        load_model(tmp_path / "missing.npz")
    old = tmp_path / "old.npz"
    with np.load(path) as npz:
        data = {k: npz[k] for k in npz.files}
    header = json.loads(data["header"].tobytes())
    header["version"] = 99
    data["header"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    np.savez(old, **data)
    with pytest.raises(ModelFileError, match="version 99"):
        load_model(old)
    # A NUL byte in an array's .npy header (numpy parses it as Python: a SyntaxError inside).
    nul = tmp_path / "nul.npz"
    with zipfile.ZipFile(path) as src, zipfile.ZipFile(nul, "w") as dst:
        for info in src.infolist():
            blob = src.read(info)
            if info.filename == "patterns.npy":
                blob = blob.replace(b"'shape': (", b"'shape': \x00", 1)
            dst.writestr(info, blob)
    with pytest.raises(ModelFileError, match="not a monitor model file .an array header"):
        load_model(nul)


def test_a_recording_without_the_model_signals_is_refused(small_model):
    rec = simulate(make_cycle("boom", 10, 5), MACHINE, seed=5)
    del rec.columns["PB"]
    with pytest.raises(InputFileError, match="PB"):
        detect(small_model, rec)
    short = Recording(rec.t[:2], {k: v[:2] for k, v in rec.columns.items()})
    short.columns["PB"] = np.zeros(2)
    with pytest.raises(InputFileError, match="too few"):
        detect(small_model, short)


def test_missing_samples_are_a_sensor_fault_not_a_hydraulic_one(small_model):
    rec = simulate(make_cycle("boom", 30, 21), MACHINE, seed=21)
    rec.columns["PA"][1500:1600] = np.nan  # a pressure sensor drops out for a second
    det = detect(small_model, rec)
    assert det.summary["sensor_fault"] is True
    assert det.summary["alarm"] is False
    states = [e["state"] for e in det.events]
    assert states[:3] == ["normal", "sensor_fault", "normal"]


def test_engine_off_is_inactive(small_model):
    rec = simulate(make_cycle("boom", 30, 22), MACHINE, seed=22)
    rec.columns["EngineSpeed"][1000:2000] = 0.0
    det = detect(small_model, rec)
    assert [e["state"] for e in det.events][:3] == ["normal", "inactive", "normal"]
    assert det.summary["inactive_fraction"] == pytest.approx(1000 / 3001)


def test_train_and_detect_cli(tmp_path, capsys):
    paths = []
    for seed in (31, 32, 33):
        p = tmp_path / f"n{seed}.csv"
        write_csv(p, simulate(make_cycle("boom", 90, seed), MACHINE, seed=seed))
        paths.append(str(p))
    model = tmp_path / "m.npz"
    assert (
        main(
            [
                "train",
                *paths,
                "--out",
                str(model),
                "--max-patterns",
                "400",
                "--window",
                "300",
                "--isolation",
                "none",
            ]
        )
        == 0
    )
    fault = tmp_path / "f.csv"
    # Oil as warm as in the first training run: a run at another temperature would lie
    # outside the model's trained range, and would (rightly) not be judged.
    cycle = make_cycle("boom", 90, 34)
    cycle.columns["OilTemp"] = make_cycle("boom", 90, 31)["OilTemp"]
    write_csv(
        fault,
        simulate(cycle, MACHINE, faults=[Fault("spool_wear", 1.0, 30.0)], seed=34),
    )
    summary, events, plot = tmp_path / "s.json", tmp_path / "e.jsonl", tmp_path / "p.png"
    assert (
        main(
            [
                "detect",
                str(fault),
                "--model",
                str(model),
                "--summary",
                str(summary),
                "--events",
                str(events),
                "--plot",
                str(plot),
            ]
        )
        == 0
    )
    s = json.loads(summary.read_text())
    for key in ("alarm", "first_alarm_t", "fault", "sensor_fault", "max_J", "threshold"):
        assert key in s
    assert s["verdict"] in ("fault", "healthy") and s["judged_s"] > 0
    lines = [json.loads(x) for x in events.read_text().splitlines()]
    assert {"t", "time", "state", "J", "threshold", "fault"} <= set(lines[0])
    assert plot.stat().st_size > 10_000
    if s["alarm"]:
        assert s["first_alarm_t"] > 30.0  # never before the onset on this run


def test_train_isolation_runs_sets_the_simulated_runs(tmp_path, capsys):
    """``--isolation-runs N`` learns each fault's signature from N simulated runs per
    severity: 3 faults x 4 severities x 1 run = 12 runs, not the default 2 x 12 = 24."""
    p = tmp_path / "n.csv"
    write_csv(p, simulate(make_cycle("boom", 150, 41), MACHINE, seed=41))
    model = tmp_path / "m.npz"
    argv = ["train", str(p), "--out", str(model), "--max-patterns", "200", "--window", "300"]
    assert main([*argv, "--isolation-runs", "1"]) == 0
    said = capsys.readouterr().err
    assert "learning fault signatures from 12 simulated runs" in said
    # The shipped config declares the reference machine: the model records it.
    assert "commissioned on machine 'reference'" in said
    assert load_model(model).card.machine_id == "reference"
    assert load_model(model).isolation.labels == tuple(
        f for f in ("piston_wear", "spool_stroke", "spool_wear") for _ in range(4)
    )


def test_cli_user_errors_are_one_line(tmp_path, capsys):
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    assert main(["detect", str(empty)]) == 2
    assert main(["train", str(empty), "--out", str(tmp_path / "m.npz")]) == 2
    assert main(["detect", str(tmp_path / "nope.csv")]) == 2
    junk = tmp_path / "junk.npz"
    junk.write_text("x")
    rec = tmp_path / "r.csv"
    write_csv(rec, simulate(make_cycle("boom", 5, 1), MACHINE, seed=1))
    assert main(["detect", str(rec), "--model", str(junk)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 4 and all(line.startswith("monitor ") for line in err)
    assert "Traceback" not in "\n".join(err)


def test_shipped_model_on_shipped_logs():
    """The packaged model against the packaged demo logs: no alarm on the normal log, the
    spool-wear log alarms after its onset at 45 s and names the fault."""
    model = load_model(resource_path("config", "boom_default.model.npz"))
    from naive_frames import recording_from_candump

    normal = detect(model, recording_from_candump(resource_path("replay", "normal.log")))
    assert normal.summary["alarm"] is False
    wear = detect(model, recording_from_candump(resource_path("replay", "spool_wear.log")))
    assert wear.summary["alarm"] is True
    assert 45.0 < wear.summary["first_alarm_t"] < 70.0
    assert wear.summary["fault"] == "spool_wear"


def test_csv_and_candump_give_the_same_verdict(tmp_path):
    model = load_model(resource_path("config", "boom_default.model.npz"))
    csv, log = tmp_path / "w.csv", tmp_path / "w.log"
    args = ["--duration", "90", "--seed", "9004", "--fault", "spool_wear:0.6@45"]
    assert main(["simulate", *args, "--out", str(csv)]) == 0
    assert main(["simulate", *args, "--out", str(log)]) == 0
    from naive_frames import recording_from_candump

    a = detect(model, read_csv(csv)).summary
    b = detect(model, recording_from_candump(log)).summary
    assert a["alarm"] == b["alarm"]
    if a["alarm"]:
        assert a["first_alarm_t"] == pytest.approx(b["first_alarm_t"], abs=0.05)
