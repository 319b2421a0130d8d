"""``monitor encode CSV --out LOG`` through the CLI entry point."""

from __future__ import annotations

import numpy as np
from naive_frames import recording_from_candump

from monitor.cli import main
from monitor.io.csvio import write_csv
from monitor.io.recording import Recording
from monitor.signals import CSV_COLUMNS, SIGNAL_NAMES


def _csv(tmp_path, n: int = 150):
    t = np.arange(n) * 0.01
    cols = {name: np.full(n, 10.0) for name in SIGNAL_NAMES}
    cols["PP"] = 100 + t
    cols["RodPos"] = 5 * t
    p = tmp_path / "rec.csv"
    write_csv(p, Recording(t, cols))
    return p


def test_encode_writes_decodable_log_and_one_summary_line(tmp_path, capsys) -> None:
    csv_path, log = _csv(tmp_path), tmp_path / "out.log"
    assert main(["encode", str(csv_path), "--out", str(log)]) == 0
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1
    assert "602 frames from 150 rows" in out[0]
    assert "HYD_Pressures 150" in out[0] and "HYD_OilTemp 2" in out[0]
    rec = recording_from_candump(log)
    assert len(rec) == 150
    np.testing.assert_allclose(rec["PP"], 100 + np.arange(150) * 0.01, atol=0.005 + 1e-9)
    assert "RodPos" in rec.columns


def test_encode_start_time_and_channel(tmp_path, capsys) -> None:
    log = tmp_path / "out.log"
    args = [
        "encode",
        str(_csv(tmp_path)),
        "--out",
        str(log),
        "--start-time",
        "1.5",
        "--channel",
        "vcan0",
    ]
    assert main(args) == 0
    assert log.read_text().startswith("(1.500000) vcan0 0CFF1021#")


def test_bad_csv_exits_2_with_one_line(tmp_path, capsys) -> None:
    bad = tmp_path / "bad.csv"
    bad.write_text(",".join(CSV_COLUMNS) + "\n0,1,2,3,4,5,6,7,8\n0.01,1,2,3,4,oops,6,7,8\n")
    assert main(["encode", str(bad), "--out", str(tmp_path / "x.log")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "bad.csv:3" in err[0] and "PP" in err[0] and err[0].startswith("monitor encode: error")
    assert not (tmp_path / "x.log").exists()


def test_missing_csv_and_bad_dbc_exit_2(tmp_path, capsys) -> None:
    assert main(["encode", str(tmp_path / "none.csv"), "--out", str(tmp_path / "x.log")]) == 2
    assert "none.csv" in capsys.readouterr().err
    args = [
        "encode",
        str(_csv(tmp_path)),
        "--out",
        str(tmp_path / "x.log"),
        "--dbc",
        str(tmp_path / "none.dbc"),
    ]
    assert main(args) == 2
    assert "none.dbc" in capsys.readouterr().err


def test_help_lists_units(capsys) -> None:
    assert main(["encode", "--help"]) == 0
    text = capsys.readouterr().out
    for unit in ("[s", "[%", "[rpm]", "[degC]", "[bar", "[L/min]", "[mm]"):
        assert unit in text
