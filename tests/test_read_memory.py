"""Reading memory bounded by the data kept, not by the file's lines: a candump log of blank
lines costs one block of work arrays, a CSV its float columns and one block of text rows.
Measured with tracemalloc (numpy's allocations included), deterministic on a small case; the
peak RSS figures are in docs/benchmarks.md."""

from __future__ import annotations

import tracemalloc
from pathlib import Path

import pytest

from monitor.io.candump_bulk import read_candump_frames
from monitor.io.csvio import BLOCK_ROWS, read_csv
from monitor.resources import resource_path


def _peak(fn, *args):  # noqa: ANN001, ANN202
    fn(*args)  # warm: imports and compiled kernels are not the reading's
    tracemalloc.start()
    try:
        out = fn(*args)
        return out, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_a_log_of_blank_lines_costs_a_block_not_its_lines(tmp_path: Path) -> None:
    # 2 M blank lines: some 180 MB of per-line arrays and Python ints when read whole.
    small, big = tmp_path / "small.log", tmp_path / "big.log"
    small.write_bytes(b"\n" * 250_000)
    big.write_bytes(b"\n" * 2_000_000)
    frames, peak_small = _peak(read_candump_frames, small)
    assert len(frames) == 0
    frames, peak_big = _peak(read_candump_frames, big)
    assert len(frames) == 0
    assert peak_big < 24e6
    assert peak_big < 1.5 * peak_small + 4e6  # 8x the lines, about the same memory


def test_a_log_read_in_blocks_gives_the_frames_read_whole(tmp_path: Path, monkeypatch) -> None:
    from monitor.io import candump_bulk

    log = resource_path("replay", "spool_wear.log")
    whole = read_candump_frames(log)
    monkeypatch.setattr(candump_bulk, "_BLOCK", 4096)
    monkeypatch.setattr(candump_bulk, "_CHUNK", 1000)  # blocks end mid-line in the chunks
    pieces = read_candump_frames(log)
    for name in ("timestamp", "can_id", "extended", "remote", "error", "length", "data"):
        assert (getattr(pieces, name) == getattr(whole, name)).all(), name
    # A malformed line in a later block is named with its line in the file.
    lines = log.read_text().splitlines(keepends=True)[:3000]
    lines[2500] = "(1700000000.000000) can0 0CFF1021#ZZ\n"
    bad = tmp_path / "bad.log"
    bad.write_text("".join(lines))
    from monitor.errors import InputFileError

    with pytest.raises(InputFileError, match=r"bad\.log:2501: "):
        read_candump_frames(bad)


def test_a_csv_costs_its_columns_not_its_rows_as_text(tmp_path: Path, monkeypatch) -> None:
    from monitor.io import csvio

    monkeypatch.setattr(csvio, "BLOCK_ROWS", 4096)
    n = 40_000
    path = tmp_path / "rows.csv"
    with path.open("w") as fh:
        fh.write("t,SpoolCmd,PumpDispCmd,EngineSpeed,OilTemp,PP,PA,PB,QP\n")
        fh.writelines(
            f"{i / 100:.2f},{i % 200 - 100},100,2200,45.5,{100 + i % 50}.25,80.5,20.25,15.5\n"
            for i in range(n)
        )
    rec, peak = _peak(read_csv, path)
    kept = rec.t.nbytes + sum(v.nbytes for v in rec.columns.values())
    assert kept == n * 9 * 8
    # Text rows held whole: some 12x the columns kept; a block of rows at a time: under 4x.
    assert peak < 4 * kept, peak
    assert rec["PP"][12345] == 100 + 12345 % 50 + 0.25


def test_a_text_column_met_in_a_later_block_is_dropped_whole(tmp_path: Path) -> None:
    n = BLOCK_ROWS + 10
    path = tmp_path / "notes.csv"
    notes = ["1.5"] * n
    notes[-1] = "valve changed"
    with path.open("w") as fh:
        fh.write("t,SpoolCmd,PumpDispCmd,EngineSpeed,OilTemp,PP,PA,PB,QP,note\n")
        fh.writelines(f"{i / 100:.2f},0,100,2200,45,100,80,20,15,{notes[i]}\n" for i in range(n))
    rec = read_csv(path)
    assert "note" not in rec.columns and rec.meta["dropped_columns"] == ["note"]
    assert len(rec) == n
