"""Limits on what a candump log or a CSV may ask of the readers: rows per log, timestamp
range, line length, text only.  Every refusal is an ``InputFileError`` naming the file
(and line), raised before memory in proportion to the bad input is spent."""

from __future__ import annotations

import os
import random
import subprocess
import sys
import tracemalloc
from pathlib import Path

import pytest
from naive_frames import recording_from_candump

from monitor.errors import InputFileError
from monitor.io.candump import read_candump
from monitor.io.candump_bulk import read_candump_frames
from monitor.io.csvio import read_csv
from monitor.resources import resource_path
from monitor.sampling.bulk import recording_from_candump_bulk
from monitor.sampling.read import read_recording

REPLAY = sorted(resource_path("replay", "normal.log").parent.glob("*.log"))
PRESSURES = "0CFF1021"  # HYD_Pressures: PP, PA, PB


def _pressure_frames(n: int) -> list[str]:
    """The first ``n`` HYD_Pressures lines of a shipped log, without their timestamps (in
    order, so their alive counters run on)."""
    lines = resource_path("replay", "spool_wear.log").read_text().splitlines()
    return [x[x.index(")") + 1 :] for x in lines if PRESSURES in x][:n]


def _spaced_log(path: Path, n: int, step_s: float) -> Path:
    """``n`` pressure frames ``step_s`` apart (under the sampler's 60 s gap limit)."""
    path.write_text(
        "".join(
            f"({1_700_000_000 + i * step_s:.6f}){rest}\n"
            for i, rest in enumerate(_pressure_frames(n))
        )
    )
    return path


BOTH = pytest.mark.parametrize(
    "reader", [recording_from_candump_bulk, recording_from_candump], ids=["bulk", "frame"]
)
READERS = pytest.mark.parametrize(
    "read", [read_candump_frames, lambda p: list(read_candump(p))], ids=["bulk", "python-can"]
)


# ------------------------------------------------------------------------------- rows


@BOTH
def test_sparse_log_under_an_hour_of_rows_is_read(tmp_path, reader) -> None:
    # 59 gaps of 59.9 s: 59 * 5990 + 1 = 353,411 rows, under 360,000 (one hour at 100 Hz).
    # The limit counts every row; the first 301 (to 3 s, the deadline of the 1 Hz OilTemp,
    # which this log never sends) are warming and not handed out.
    rec = reader(_spaced_log(tmp_path / "s.log", 60, 59.9))
    assert len(rec.t) == 59 * 5990 + 1 - 301


@BOTH
def test_log_needing_more_rows_than_the_limit_is_refused(tmp_path, reader) -> None:
    # 61 gaps: 365,391 rows for 62 frames, over max(360,000, 20 * 62).
    log = _spaced_log(tmp_path / "s.log", 62, 59.9)
    with pytest.raises(InputFileError) as err:
        reader(log)
    msg = str(err.value)
    assert "\n" not in msg
    assert msg.startswith(
        f"{log}: would need 365391 rows of 10 ms for 62 frames spanning "
        "3653.9 s of log time, more than the limit of 360000"
    )
    assert "split it" in msg


def _refusals(log: Path) -> list[str]:
    """The messages both candump paths (bulk, frame by frame) refuse ``log`` with."""
    errors = []
    for reader in (recording_from_candump_bulk, recording_from_candump):
        with pytest.raises(InputFileError) as err:
            reader(log)
        errors.append(str(err.value))
    return errors


def test_shuffled_log_is_refused_the_same_by_both_paths(tmp_path) -> None:
    """A shuffled log (every frame out of order) makes the clock resync again and again."""
    lines = resource_path("replay", "spool_wear.log").read_text().splitlines(keepends=True)
    head = lines[:8000]
    random.Random(0).shuffle(head)
    log = tmp_path / "shuf.log"
    log.write_text("".join(head))
    errors = _refusals(log)
    assert errors[0] == errors[1]
    # Most of its frames are out of counter sequence and never reach the clock; those that
    # do still run backwards: refused, the log named, its timestamps to fix or sort.
    assert errors[0].startswith(f"{log}: its clock runs backwards: ")
    assert errors[0].endswith("a reversed log? fix or sort its timestamps")


def test_reversed_log_is_refused_like_a_shuffled_one(tmp_path) -> None:
    """A time-reversed log needs few rows (its clock resyncs after every few frames) but
    every frame comes older than the one before it: refused, not judged with a counter jump
    at every frame."""
    lines = resource_path("replay", "spool_wear.log").read_text().splitlines(keepends=True)
    head = lines[:8000]
    log = tmp_path / "rev.log"
    log.write_text("".join(reversed(head)))
    errors = _refusals(log)
    assert errors[0] == errors[1]
    assert errors[0].startswith(f"{log}: its clock runs backwards: ")
    assert " frames (" in errors[0]  # the frames that reached the clock
    assert errors[0].endswith("a reversed log? fix or sort its timestamps")
    # The log in its own order is read.
    log.write_text("".join(head))
    assert len(recording_from_candump_bulk(log)) > 0


@pytest.mark.parametrize("path", REPLAY, ids=lambda p: p.name)
def test_shipped_logs_stay_far_below_the_row_limit(path) -> None:
    rec = recording_from_candump_bulk(path)
    frames = rec.meta["counts"]["frames"]
    assert len(rec.t) < frames  # about 0.25 rows per frame; the limit is 20


# ------------------------------------------------------------------------- timestamps

GOOD = "(1700000000.000000) can0 0CFF1021#114EFD07EF0000E4\n"


@READERS
@pytest.mark.parametrize(
    ("stamp", "problem"),
    [
        ("100000000000000000000.000000", "timestamp with 21 digits before the point"),
        ("1" * 400 + ".0", "timestamp with 400 digits before the point"),
        ("100000000000.001", r"timestamp 100000000000\.001 s out of range \(0 to 1e11 s\)"),
        ("99999999999999999.5", r"timestamp 99999999999999999\.5 s out of range"),
        ("0" * 21 + "1.5", "timestamp with 22 digits before the point"),
    ],
)
def test_timestamp_out_of_range_is_a_malformed_line(tmp_path, read, stamp, problem) -> None:
    log = tmp_path / "ts.log"
    log.write_text(GOOD + f"({stamp}) can0 0CFF1021#114EFD07EF0000E4\n" + GOOD)
    with pytest.raises(InputFileError, match=rf"ts\.log:2: {problem}") as err:
        read(log)
    assert len(str(err.value)) < len(str(log)) + 200  # the line is cut, not shown whole


@READERS
def test_timestamps_at_the_limits_are_read(tmp_path, read) -> None:
    log = tmp_path / "ts.log"
    stamps = ["0.000000", "100000000000.000000", "0" * 19 + "1.5"]
    log.write_text("".join(f"({s}) can0 123#00\n" for s in stamps))
    got = read(log)
    ts = got.timestamp.tolist() if hasattr(got, "timestamp") else [m.timestamp for m in got]
    assert ts == [0.0, 1e11, 1.5]


@READERS
def test_torn_last_line_with_a_bad_timestamp_is_skipped_as_torn(tmp_path, read) -> None:
    log = tmp_path / "torn.log"
    log.write_text(GOOD + "(1" + "0" * 30 + ".0) can0 123#00")  # no newline: a torn line
    assert len(read(log)) == 1


# ---------------------------------------------------------------------- not text / long


@READERS
def test_line_over_1000_bytes_is_refused(tmp_path, read) -> None:
    log = tmp_path / "long.log"
    log.write_text(GOOD + "#" * 1000 + "\r\n" + GOOD + "y" * 1001 + "\n" + GOOD)
    with pytest.raises(InputFileError, match=r"long\.log:4: line longer than 1000 bytes"):
        read(log)
    log.write_text(GOOD + "y" * 1001)  # unterminated: not a torn candump line either
    with pytest.raises(InputFileError, match=r"long\.log:2: line longer than 1000 bytes"):
        read(log)


@READERS
def test_nul_bytes_in_a_line_are_refused(tmp_path, read) -> None:
    log = tmp_path / "nul.log"
    log.write_bytes((GOOD + "(1700000000.1) can0 123#00\0\0\n" + GOOD).encode())
    with pytest.raises(InputFileError, match=r"nul\.log:2: NUL bytes, not a text log"):
        read(log)


@READERS
def test_nul_bytes_in_a_torn_last_line_are_skipped_as_torn(tmp_path, read) -> None:
    log = tmp_path / "nul.log"
    log.write_bytes((GOOD * 3).encode() + b"\0" * 100)  # a power cut's zeroed tail
    assert len(read(log)) == 3


def _peak_bytes(fn) -> int:
    tracemalloc.start()
    try:
        fn()
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    return peak


@pytest.mark.parametrize(
    "read",
    [
        read_candump_frames,
        lambda p: list(read_candump(p)),
        read_recording,
        recording_from_candump,
        read_csv,
    ],
    ids=["bulk", "python-can", "read_recording", "frame", "csv"],
)
def test_sparse_file_is_refused_reading_a_little_of_it(tmp_path, read) -> None:
    """A 1 GB sparse file (all NULs, no newline) is refused at its first line, having read
    a chunk of it, not the gigabyte (numpy's and Python's allocations are both traced)."""
    path = tmp_path / "sparse.log"
    with path.open("wb"):
        pass
    os.truncate(path, 1 << 30)

    def refuse() -> None:
        with pytest.raises(InputFileError, match=r"sparse\.log:1: line longer than"):
            read(path)

    assert _peak_bytes(refuse) < 32 << 20


def test_csv_with_nul_bytes_is_refused(tmp_path) -> None:
    path = tmp_path / "r.csv"
    # A full header: the header is checked before any row is read.
    path.write_bytes(b"t,SpoolCmd,PumpDispCmd,EngineSpeed,OilTemp,PP,PA,PB,QP\n0.0,1\0\n")
    with pytest.raises(InputFileError, match=r"r\.csv:2: NUL bytes, not a text file"):
        read_csv(path)


def test_cli_refuses_a_sparse_log_in_one_line(tmp_path) -> None:
    path = tmp_path / "sparse.log"
    with path.open("wb"):
        pass
    os.truncate(path, 1 << 31)
    out = subprocess.run(
        [sys.executable, "-m", "monitor", "detect", str(path)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 2
    assert out.stderr.strip() == (
        f"monitor detect: error: {path}:1: line longer than 1000 bytes, not a candump -L log"
        " (a binary or corrupt file?)"
    )
