"""Contract CSV reading and writing."""

from __future__ import annotations

import math

import numpy as np
import pytest

from monitor.errors import InputFileError
from monitor.io.csvio import read_csv, write_csv
from monitor.io.recording import Recording
from monitor.signals import CSV_COLUMNS, SIGNAL_NAMES

HEADER = ",".join(CSV_COLUMNS)


def _row(t: float, pp: str = "100.5") -> str:
    # t, SpoolCmd, PumpDispCmd, EngineSpeed, OilTemp, PP, PA, PB, QP
    return f"{t},10,100,2200,45,{pp},80,20,15.5"


def _write(tmp_path, text: str, name: str = "rec.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_reads_contract_csv_any_order_with_extra_column(tmp_path) -> None:
    cols = [
        "QP",
        "PP",
        "t",
        "RodPos",
        "SpoolCmd",
        "PumpDispCmd",
        "EngineSpeed",
        "OilTemp",
        "PA",
        "PB",
    ]
    lines = [",".join(cols), "1.5,100,0.00,12.5,10,100,2200,45,80,20", "1.6,101,0.01,13,,,,,,"]
    rec = read_csv(_write(tmp_path, "\n".join(lines) + "\n"))
    assert rec.t.tolist() == [0.0, 0.01]
    assert rec["QP"].tolist() == [1.5, 1.6]
    assert rec["RodPos"].tolist() == [12.5, 13.0]
    assert rec["PP"].tolist() == [100.0, 101.0]
    # empty field = missing sample (NaN), not an error
    assert math.isnan(rec["SpoolCmd"][1]) and math.isnan(rec["PB"][1])
    rec.require()


def test_missing_required_column_names_header_line(tmp_path) -> None:
    header = HEADER.replace(",PB", "")
    p = _write(tmp_path, header + "\n0,10,100,2200,45,100,80,15\n")
    with pytest.raises(InputFileError, match=r"rec\.csv:1: missing required column\(s\) PB"):
        read_csv(p)


def test_text_value_names_line_and_column(tmp_path) -> None:
    text = "\n".join([HEADER, _row(0.0), _row(0.01, pp="high"), _row(0.02)]) + "\n"
    with pytest.raises(InputFileError, match=r"rec\.csv:3: column 'PP': 'high' is not a number"):
        read_csv(_write(tmp_path, text))


def test_short_row_names_line(tmp_path) -> None:
    text = "\n".join([HEADER, _row(0.0), _row(0.01), "0.02,10,100"]) + "\n"
    with pytest.raises(InputFileError, match=r"rec\.csv:4: 3 fields, the header has 9"):
        read_csv(_write(tmp_path, text))


def test_non_increasing_time_names_line(tmp_path) -> None:
    text = "\n".join([HEADER, _row(0.0), _row(0.01), _row(0.01)]) + "\n"
    with pytest.raises(InputFileError, match=r"rec\.csv:4: column 't'"):
        read_csv(_write(tmp_path, text))


def test_missing_time_and_infinite_value(tmp_path) -> None:
    text = "\n".join([HEADER, _row(0.0), ",10,100,2200,45,1,80,20,15"]) + "\n"
    with pytest.raises(InputFileError, match=r"rec\.csv:3: column 't': time is missing"):
        read_csv(_write(tmp_path, text))
    text = "\n".join([HEADER, _row(0.0), _row(0.01, pp="inf")]) + "\n"
    with pytest.raises(InputFileError, match=r"rec\.csv:3: column 'PP'"):
        read_csv(_write(tmp_path, text))


def test_empty_and_header_only_and_missing_file(tmp_path) -> None:
    with pytest.raises(InputFileError, match="empty file"):
        read_csv(_write(tmp_path, ""))
    with pytest.raises(InputFileError, match="no data rows"):
        read_csv(_write(tmp_path, HEADER + "\n"))
    with pytest.raises(InputFileError, match="nope.csv"):
        read_csv(tmp_path / "nope.csv")


def test_blank_lines_skipped_and_line_numbers_kept(tmp_path) -> None:
    text = "\n".join([HEADER, _row(0.0), "", _row(0.01), _row(0.02, pp="x")]) + "\n"
    with pytest.raises(InputFileError, match=r":5: column 'PP'"):
        read_csv(_write(tmp_path, text))


def test_extra_text_column_is_dropped_not_an_error(tmp_path) -> None:
    text = HEADER + ",phase\n" + _row(0.0) + ",raise\n" + _row(0.01) + ",hold\n"
    rec = read_csv(_write(tmp_path, text))
    assert "phase" not in rec.columns
    assert rec.meta["dropped_columns"] == ["phase"]


def test_write_read_round_trip(tmp_path) -> None:
    n = 500
    rng = np.random.default_rng(3)
    t = np.arange(n) * 0.01 + rng.uniform(-0.002, 0.002, n)  # jitter of a few ms
    cols = {name: rng.uniform(-100, 3000, n) for name in SIGNAL_NAMES}
    cols["RodPos"] = rng.uniform(0, 500, n)
    cols["PP"][[3, 10]] = np.nan
    rec = Recording(t, cols)
    p = tmp_path / "out.csv"
    write_csv(p, rec)
    header = p.read_text().splitlines()[0].split(",")
    assert header == [*CSV_COLUMNS, "RodPos"]
    back = read_csv(p)
    assert np.allclose(back.t, t, atol=1e-6, rtol=0)
    for name, values in cols.items():
        np.testing.assert_allclose(back[name], values, rtol=1e-9, atol=1e-9)
    assert np.isnan(back["PP"][[3, 10]]).all()
    write_csv(tmp_path / "contract_only.csv", rec, extra_columns=())
    assert "RodPos" not in read_csv(tmp_path / "contract_only.csv").columns


def test_write_requires_contract_signals(tmp_path) -> None:
    rec = Recording(np.arange(3) * 0.01, {"PP": np.zeros(3)})
    with pytest.raises(InputFileError, match="missing required signal"):
        write_csv(tmp_path / "x.csv", rec)


def test_reads_60000_rows(tmp_path) -> None:
    n = 60_000
    rec = Recording(np.arange(n) * 0.01, {name: np.full(n, 1.25) for name in SIGNAL_NAMES})
    p = tmp_path / "big.csv"
    write_csv(p, rec)
    back = read_csv(p)
    assert len(back) == n and back.t[-1] == pytest.approx(599.99)
    assert (back["QP"] == 1.25).all()
