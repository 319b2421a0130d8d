"""candump logs: writing a Recording as DBC frames, reading logs (ours and real ones) back."""

from __future__ import annotations

import logging
import re
from pathlib import Path

import numpy as np
import pytest
from can.io.canutils import CanutilsLogReader
from naive import crc8_bitwise
from shared_data import BAD_LOGS, GOOD_LOGS, REAL_LOGS

from monitor.codec import load_dbc
from monitor.codec.logwrite import write_candump
from monitor.errors import InputFileError
from monitor.io.candump import read_candump
from monitor.io.candump_bulk import read_candump_frames
from monitor.io.recording import Recording
from monitor.resources import resource_path

needs_real_logs = pytest.mark.skipif(
    not REAL_LOGS.is_dir(), reason=f"shared real CAN logs not found at {REAL_LOGS}"
)

CANDUMP_LINE = re.compile(r"\((\d+\.\d{6})\) can0 ([0-9A-F]{8})#([0-9A-F]{16})")
IDS = {
    "HYD_Pressures": 0x0CFF1021,
    "HYD_Flow": 0x0CFF1121,
    "HYD_RodPos": 0x0CFF1421,
    "HYD_Commands": 0x0CFF1203,
    "HYD_OilTemp": 0x18FF1300,
}


def make_recording(n: int = 250, rod: bool = True) -> Recording:
    t = np.arange(n) * 0.01
    cols = {
        "SpoolCmd": 80 * np.sin(t),
        "PumpDispCmd": np.full(n, 100.0),
        "EngineSpeed": np.full(n, 2200.0),
        "OilTemp": 40 + 0.5 * np.floor(t),
        "PP": 150 + 20 * np.sin(3 * t),
        "PA": 100 + 10 * np.cos(t),
        "PB": 20 + t,
        "QP": 24 + np.sin(5 * t),
    }
    if rod:
        cols["RodPos"] = 250 + 100 * np.sin(t)
    return Recording(t, cols)


def test_log_format_counters_crc_and_frame_counts(tmp_path) -> None:
    rec = make_recording(250)
    log = tmp_path / "x.log"
    counts = write_candump(log, rec)
    # 250 rows of 2.49 s: 10 ms frames on every row, oil temperature at 0, 1 and 2 s
    assert counts == {
        "HYD_Pressures": 250,
        "HYD_Flow": 250,
        "HYD_RodPos": 250,
        "HYD_Commands": 250,
        "HYD_OilTemp": 3,
    }
    lines = log.read_text().splitlines()
    assert len(lines) == sum(counts.values())
    assert lines[0].startswith("(1700000000.000000) can0 0CFF1021#")
    last_counter: dict[int, int] = {}
    times = []
    for line in lines:
        m = CANDUMP_LINE.fullmatch(line)
        assert m, line
        times.append(float(m[1]))
        ident, data = int(m[2], 16), bytes.fromhex(m[3])
        assert data[7] == crc8_bitwise(data[:7])
        counter = data[6] & 0x0F
        if ident in last_counter:
            assert counter == (last_counter[ident] + 1) % 16
        else:
            assert counter == 0
        last_counter[ident] = counter
    assert times == sorted(times)
    oil = [float(CANDUMP_LINE.fullmatch(x)[1]) for x in lines if " 18FF1300#" in x]
    assert oil == [1700000000.0, 1700000001.0, 1700000002.0]


def test_python_can_and_cantools_read_our_log(tmp_path) -> None:
    rec = make_recording(120)
    log = tmp_path / "x.log"
    write_candump(log, rec, start_time_s=1_600_000_000.0)
    msgs = list(CanutilsLogReader(log))
    assert len(msgs) == 4 * 120 + 2
    db = load_dbc()
    pp = [
        db.decode_message(m.arbitration_id, m.data)["PP"]
        for m in msgs
        if m.arbitration_id == IDS["HYD_Pressures"]
    ]
    np.testing.assert_allclose(pp, rec["PP"], atol=0.005 + 1e-9)
    first = msgs[0]
    assert first.is_extended_id and first.dlc == 8
    assert first.timestamp == pytest.approx(1_600_000_000.0)
    assert msgs[-1].timestamp == pytest.approx(1_600_000_000.0 + 1.19, abs=1e-6)
    # our reader gives the same messages
    ours = list(read_candump(log))
    assert [(m.arbitration_id, bytes(m.data), m.timestamp) for m in ours] == [
        (m.arbitration_id, bytes(m.data), m.timestamp) for m in msgs
    ]


def test_without_rodpos_and_nan_rows_skip_frames(tmp_path) -> None:
    rec = make_recording(100, rod=False)
    rec.columns["PA"][10] = np.nan  # kills the whole pressures frame of row 10
    rec.columns["QP"][20:23] = np.nan
    rec.columns["OilTemp"][0] = np.nan  # the first oil frame goes out at the next row
    counts = write_candump(tmp_path / "x.log", rec)
    assert counts == {"HYD_Pressures": 99, "HYD_Flow": 97, "HYD_Commands": 100, "HYD_OilTemp": 1}
    text = (tmp_path / "x.log").read_text()
    assert "(1700000000.100000) can0 0CFF1021#" not in text
    assert "(1700000000.010000) can0 18FF1300#" in text


def test_values_are_clipped_to_dbc_range(tmp_path) -> None:
    rec = make_recording(5)
    rec.columns["PP"][:] = 999.0
    rec.columns["QP"][:] = -5.0
    write_candump(tmp_path / "x.log", rec)
    db = load_dbc()
    msgs = list(read_candump(tmp_path / "x.log"))
    pp = {
        db.decode_message(m.arbitration_id, m.data)["PP"]
        for m in msgs
        if m.arbitration_id == IDS["HYD_Pressures"]
    }
    qp = {
        db.decode_message(m.arbitration_id, m.data)["QP"]
        for m in msgs
        if m.arbitration_id == IDS["HYD_Flow"]
    }
    assert pp == {400.0} and qp == {0.0}


@pytest.mark.parametrize(
    "bad_line",
    [
        "0x1dc",
        "(1606770",
        "(1.0) can0 123#ABC",
        "(1.0) can0 1234#00",
        "(1.0) can0 123#GG",
        "(1.0) can0 123#001122334455667788",
        "1.0 can0 123#00",
        "(1.0) can0",
    ],
)
def test_malformed_lines_name_file_and_line(tmp_path, bad_line: str) -> None:
    log = tmp_path / "bad.log"
    log.write_text("(1.000000) can0 123#00\n\n(1.1) can0 12345678#0011 R\n" + bad_line + "\n")
    with pytest.raises(InputFileError, match=r"bad\.log:4: not a candump -L line"):
        list(read_candump(log))


def test_accepted_line_variants(tmp_path) -> None:
    log = tmp_path / "ok.log"
    log.write_text(
        "(1.000000) can0 123#\n"  # no data
        "(1.100000) vcan0 1ABCDEF0#R\n"  # remote frame
        "(1.200000) can1 123#0011 T\n"  # python-can's direction flag
        "(1.300000) can0 123##1001122\n"  # CAN FD with flags
        "\n"
    )
    msgs = list(read_candump(log))
    assert len(msgs) == 4
    assert msgs[1].is_remote_frame and msgs[1].is_extended_id
    assert msgs[3].is_fd and bytes(msgs[3].data) == bytes([0x00, 0x11, 0x22])


def test_missing_log_file(tmp_path) -> None:
    with pytest.raises(InputFileError, match="nope.log"):
        read_candump(tmp_path / "nope.log")


@needs_real_logs
@pytest.mark.parametrize(("name", "line"), BAD_LOGS)
def test_malformed_real_logs_rejected_naming_file_and_line(name: str, line: int) -> None:
    with pytest.raises(InputFileError, match=rf"{re.escape(name)}:{line}: "):
        list(read_candump(REAL_LOGS / name))


@needs_real_logs
@pytest.mark.parametrize("name", GOOD_LOGS)
def test_good_real_logs_read(name: str) -> None:
    path = REAL_LOGS / name
    msgs = list(read_candump(path))
    expected = sum(1 for x in path.read_text().splitlines() if x.strip())
    assert len(msgs) == expected > 0
    assert all(not m.is_extended_id for m in msgs)  # passenger-car 11-bit ids


def _torn_and_commented(tmp_path: Path) -> tuple[Path, int]:
    """A shipped log with a comment header and a comment inside, cut off mid-line at its end
    (what a power cut leaves); returns the path and the number of whole frame lines."""
    lines = resource_path("replay", "normal.log").read_text().splitlines()[:500]
    text = "# candump -L can0, logger v1.2\n" + "\n".join(lines[:250]) + "\n# pause\n"
    text += "\n".join(lines[250:]) + "\n" + lines[0][:17]  # torn: no newline, half a line
    path = tmp_path / "torn.log"
    path.write_text(text)
    return path, 500


def test_torn_last_line_and_comments_are_skipped_with_one_warning(tmp_path, caplog) -> None:
    path, whole = _torn_and_commented(tmp_path)
    with caplog.at_level(logging.WARNING, logger="monitor"):
        slow = list(read_candump(path))
        bulk = read_candump_frames(path)
    assert len(slow) == whole and len(bulk) == whole
    torn = [r for r in caplog.records if "torn last line" in r.getMessage()]
    assert len(torn) == 2  # one per reader
    assert all(f"{path}:503:" in r.getMessage() for r in torn)  # 500 frames + 2 comments + 1


def test_a_malformed_line_that_is_not_the_last_is_still_an_error(tmp_path) -> None:
    lines = resource_path("replay", "normal.log").read_text().splitlines()[:20]
    lines[10] = lines[10][:17]  # the same tear, but in the middle of the file
    path = tmp_path / "mid.log"
    path.write_text("\n".join(lines) + "\n")
    for reader in (lambda p: list(read_candump(p)), read_candump_frames):
        with pytest.raises(InputFileError, match=r"mid.log:11: not a candump -L line"):
            reader(path)
