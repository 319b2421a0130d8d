"""Sampler (frames -> 100 Hz rows with staleness) and recording_from_candump."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from naive_frames import recording_from_candump
from shared_data import GOOD_LOGS, REAL_LOGS

from monitor.codec import FrameCodec
from monitor.codec.logwrite import write_candump
from monitor.errors import InputFileError, NoHydraulicDataError
from monitor.io.csvio import read_csv, write_csv
from monitor.io.recording import Recording
from monitor.sampling.sampler import ROW_COLUMNS, Sampler
from monitor.signals import SIGNAL_NAMES

# DBC resolution per signal: half a quantisation step is the largest round-trip error
HALF_STEP = {
    "SpoolCmd": 0.005,
    "PumpDispCmd": 0.005,
    "EngineSpeed": 0.0625,
    "OilTemp": 0.015625,
    "PP": 0.005,
    "PA": 0.005,
    "PB": 0.005,
    "QP": 0.005,
    "RodPos": 0.005,
}
COL = {name: 1 + i for i, name in enumerate(ROW_COLUMNS)}  # row index of each signal


def make_recording(n: int = 300, rod: bool = True) -> Recording:
    t = np.arange(n) * 0.01
    cols = {
        "SpoolCmd": 80 * np.sin(t),
        "PumpDispCmd": 60 + 30 * np.cos(2 * t),
        "EngineSpeed": 2200 + 100 * np.sin(t),
        "OilTemp": 40 + 0.5 * np.floor(t),  # changes only on the 1 s oil-frame grid
        "PP": 150 + 20 * np.sin(3 * t),
        "PA": 100 + 10 * np.cos(t),
        "PB": 20 + t,
        "QP": 24 + np.sin(5 * t),
    }
    if rod:
        cols["RodPos"] = 250 + 100 * np.sin(t)
    return Recording(t, cols)


def sampler() -> Sampler:
    """A sampler for the time and staleness rules: every column optional, so a signal these
    tests never send holds no row back (warming is tested on its own below)."""
    return Sampler({"PP": 0.01, "QP": 0.01, "OilTemp": 1.0}, optional=ROW_COLUMNS)


def test_rows_hold_latest_value_and_go_stale_after_three_cycles() -> None:
    s = sampler()
    for k in range(5):  # PP at 0..40 ms
        s.feed(100.0 + k * 0.01, "HYD_Pressures", {"PP": float(k)})
        if k == 0:
            s.feed(100.0, "HYD_OilTemp", {"OilTemp": 45.0})  # same time as the first frame
    rows = s.advance(100.15)
    assert rows.shape == (16, 1 + len(ROW_COLUMNS))
    np.testing.assert_allclose(rows[:, 0], np.arange(16) * 0.01)
    pp = rows[:, COL["PP"]]
    # latest value through 40 ms, held for 3 cycles (50..70 ms), NaN from 80 ms on
    assert pp[:8].tolist() == [0, 1, 2, 3, 4, 4, 4, 4]
    assert np.isnan(pp[8:]).all()
    assert (rows[:, COL["OilTemp"]] == 45.0).all()  # 1 s cycle: fresh for 3 s
    assert np.isnan(rows[:, COL["QP"]]).all()  # never received
    assert np.isnan(rows[:, COL["RodPos"]]).all()
    assert s.seen == {"PP", "OilTemp"}
    assert s.start_time_s == 100.0


def _pp_then_qp(k_pp: int, k_qp: int) -> np.ndarray:
    """PP every 10 ms 0.5 ms before QP (as a sender's burst orders them), PP's last frame
    k_pp, QP's k_qp; the rows up to 300 ms."""
    s = sampler()
    frames = [(100.0 + k * 0.01, "HYD_Flow", {"QP": float(k)}) for k in range(k_qp + 1)]
    frames += [
        (100.0 + k * 0.01 - 0.0005, "HYD_Pressures", {"PP": float(k)}) for k in range(1, k_pp + 1)
    ]
    for ts, name, values in sorted(frames, key=lambda f: f[0]):
        s.feed(ts, name, values)
    return s.advance(100.3)


def test_a_silent_bus_takes_every_signal_on_the_same_row() -> None:
    # The bus falls silent after PP's frame at 99.5 ms and QP's at 100 ms (sampler time).
    # By each signal's own last frame, PP would be stale at the 130 ms row (30.5 ms old)
    # and QP not (30 ms, within 3 cycles): a sensor failing where the bus went quiet.  Both
    # were on schedule, so both count from the bus's newest frame (100 ms): fresh at 130 ms,
    # stale from 140 ms on, together.
    rows = _pp_then_qp(k_pp=10, k_qp=10)
    pp, qp = rows[:, COL["PP"]], rows[:, COL["QP"]]
    assert pp[13] == 10.0 and qp[13] == 10.0
    assert np.isnan(pp[14:]).all() and np.isnan(qp[14:]).all()


def test_one_signal_missing_on_a_live_bus_is_stale_by_its_own_last_frame() -> None:
    # PP's last frame at 99.5 ms, QP going on: PP is stale from the 130 ms row (30.5 ms > 3
    # cycles), QP fresh throughout.
    rows = _pp_then_qp(k_pp=10, k_qp=29)
    pp, qp = rows[:, COL["PP"]], rows[:, COL["QP"]]
    assert pp[12] == 10.0 and np.isnan(pp[13:]).all()
    assert not np.isnan(qp[:30]).any()


def test_incremental_feed_matches_batch() -> None:
    frames = [(5.0 + k * 0.01 + 0.003, "HYD_Flow", {"QP": float(k)}) for k in range(50)]
    a, b = sampler(), sampler()
    for f in frames:
        a.feed(*f)
    batch = a.flush()
    parts = []
    for f in frames:
        b.feed(*f)
        parts.append(b.advance(f[0] - 0.002))  # ask as a live loop would, with latency
    parts.append(b.flush())
    np.testing.assert_array_equal(np.concatenate(parts), batch)
    assert len(batch) == 50  # instants 0..490 ms


def test_oil_temperature_goes_stale_after_three_seconds() -> None:
    # The flow frames keep the bus alive (a silent bus is an outage, after which staleness
    # starts afresh); only the 1 Hz oil temperature stops after its first frame.
    s = sampler()
    s.feed(0.0, "HYD_OilTemp", {"OilTemp": 50.0})
    for k in range(351):
        s.feed(0.005 + k * 0.01, "HYD_Flow", {"QP": 1.0})
    rows = s.flush()
    oil = rows[:, COL["OilTemp"]]
    assert (oil[:301] == 50.0).all() and np.isnan(oil[301:]).all()


def test_start_mid_operation_is_warming_until_every_signal_was_seen() -> None:
    """A start mid-operation: the 1 Hz OilTemp comes 0.43 s after the first frame, and RodPos
    (optional) never.  The rows before it are warming, not emitted; row t = 0 is the first
    instant with every required signal fresh."""
    cycles = {
        "SpoolCmd": 0.01,
        "PumpDispCmd": 0.01,
        "EngineSpeed": 0.01,
        "PP": 0.01,
        "PA": 0.01,
        "PB": 0.01,
        "QP": 0.01,
        "OilTemp": 1.0,
        "RodPos": 0.01,
    }
    frames = []
    for k in range(100):
        t = 50.0 + k * 0.01
        frames.append((t, "m", {n: float(k) for n in SIGNAL_NAMES if n != "OilTemp"}))
        if k == 43:
            frames.append((t + 0.004, "HYD_OilTemp", {"OilTemp": 60.0}))
    live, batch = Sampler(cycles), Sampler(cycles)
    parts = []
    for f in frames:
        live.feed(*f)
        batch.feed(*f)
        parts.append(live.advance(f[0] - 0.002))
    parts.append(live.flush())
    rows = batch.flush()
    np.testing.assert_array_equal(np.concatenate(parts), rows)
    # OilTemp at 434 ms is visible from the 440 ms instant on: 56 rows from there to 990 ms.
    assert len(rows) == 56 and rows[0, 0] == 0.0
    assert batch.start_time_s == pytest.approx(50.44) and batch.first_time_s == 50.0
    assert rows[0, COL["PP"]] == 44.0 and (rows[:, COL["OilTemp"]] == 60.0).all()
    assert np.isfinite(rows[:, 1:-1]).all() and np.isnan(rows[:, COL["RodPos"]]).all()


def test_signal_never_seen_is_stale_after_its_own_deadline() -> None:
    """A required signal that never comes stops warming at its own staleness time from the
    first frame (3 x 1 s for OilTemp), and reads stale (NaN) from there."""
    s = Sampler({"QP": 0.01, "OilTemp": 1.0}, columns=("QP", "OilTemp"))
    for k in range(400):
        s.feed(k * 0.01, "HYD_Flow", {"QP": 1.0})
    rows = s.flush()
    assert s.start_time_s == pytest.approx(3.01)  # first instant past 3 s + 1 us
    assert len(rows) == 400 - 301 and np.isnan(rows[:, 2]).all() and (rows[:, 1] == 1).all()


def test_time_backwards_jitter_stray_and_clock_reset() -> None:
    s = sampler()
    for k in range(10):
        s.feed(10.0 + k * 0.01, "HYD_Flow", {"QP": float(k)})
    s.feed(10.085, "HYD_Flow", {"QP": 100.0})  # 5 ms late: jitter, applied at 90 ms
    s.feed(9.0, "HYD_Flow", {"QP": -1.0})  # one stray frame from the past: skipped
    s.feed(10.10, "HYD_Flow", {"QP": 10.0})
    for k in range(8):  # the logger's clock was reset to 0
        s.feed(0.0 + k * 0.01, "HYD_Flow", {"QP": 20.0 + k})
    rows = s.flush()
    t = rows[:, 0]
    assert (np.diff(t) > 0).all()
    np.testing.assert_allclose(np.diff(t), 0.01)
    qp = rows[:, COL["QP"]]
    assert qp[9] == 100.0 and -1.0 not in qp
    assert qp[-1] == 27.0 and t[-1] == pytest.approx(0.18)
    assert s.counts.time_backwards == 1 + 1 + 5 and s.counts.time_skipped == 1
    assert s.counts.time_resyncs == 1


def test_long_forward_gap_is_shortened() -> None:
    s = Sampler({"QP": 0.01}, max_gap_s=2.0, optional=ROW_COLUMNS)
    s.feed(0.0, "HYD_Flow", {"QP": 1.0})
    s.feed(86400.0, "HYD_Flow", {"QP": 2.0})  # a day later
    rows = s.flush()
    assert len(rows) == 201 and rows[-1, COL["QP"]] == 2.0
    assert np.isnan(rows[4:-1, COL["QP"]]).all()
    assert s.counts.gaps_shortened == 1


def test_round_trip_csv_log_recording(tmp_path) -> None:
    rec = make_recording(300)
    csv_path, log = tmp_path / "in.csv", tmp_path / "in.log"
    write_csv(csv_path, rec)
    write_candump(log, read_csv(csv_path))
    back = recording_from_candump(log)
    assert len(back) == len(rec)
    np.testing.assert_allclose(back.t, rec.t, atol=1e-9)
    assert set(back.columns) == set(rec.columns)
    for name, step in HALF_STEP.items():
        np.testing.assert_allclose(back[name], rec[name], atol=step + 1e-9, rtol=0, err_msg=name)
    counts = back.meta["counts"]
    assert counts["frames"] == 4 * 300 + 3 and counts["decoded"] == counts["frames"]
    assert counts["ignored"] == 0 and counts["counter_jumps"] == 0
    assert counts["rejected"] == {"dlc": 0, "crc": 0, "range": 0, "sequence": 0}
    assert back.meta["start_time_s"] == pytest.approx(1_700_000_000.0)


def test_no_rodpos_column_when_log_has_none(tmp_path) -> None:
    write_candump(tmp_path / "x.log", make_recording(50, rod=False))
    back = recording_from_candump(tmp_path / "x.log")
    assert set(back.columns) == set(SIGNAL_NAMES)


def test_missing_samples_held_three_cycles_then_nan(tmp_path) -> None:
    rec = make_recording(100)
    rec.columns["PP"][10] = np.nan  # one missing sample: held
    rec.columns["QP"][40:46] = np.nan  # six missing samples: the last three are stale
    write_candump(tmp_path / "x.log", rec)
    back = recording_from_candump(tmp_path / "x.log")
    assert back["PP"][10] == pytest.approx(rec["PP"][9], abs=0.005)
    assert back["PA"][10] == pytest.approx(rec["PA"][9], abs=0.005)  # same frame
    qp = back["QP"]
    assert np.isfinite(qp[40:43]).all() and np.isnan(qp[43:46]).all() and np.isfinite(qp[46])


def _rewrite(log: Path, edit) -> None:
    lines = log.read_text().splitlines(keepends=True)
    log.write_text("".join(edit(lines)))


def test_bad_crc_wrong_dlc_and_counter_jump_counted(tmp_path) -> None:
    log = tmp_path / "x.log"
    write_candump(log, make_recording(50, rod=False))

    def edit(lines: list[str]) -> list[str]:
        out = []
        for i, line in enumerate(lines):
            head, data = line.rstrip("\n").split("#")
            if i == 10:  # flip a bit of byte 0: CRC mismatch
                data = f"{int(data[:2], 16) ^ 1:02X}" + data[2:]
            elif i == 20:  # drop the CRC byte: DLC 7
                data = data[:14]
            elif i == 30:  # a frame lost on the bus
                continue
            out.append(f"{head}#{data}\n")
        out.append("(1700000001.000000) can0 123#0011\n")  # foreign traffic
        return out

    _rewrite(log, edit)
    back = recording_from_candump(log)
    c = back.meta["counts"]
    assert c["rejected"] == {"dlc": 1, "crc": 1, "range": 0, "sequence": 0}
    assert c["ignored"] == 1
    # each rejected or lost frame breaks the counter sequence of its message once
    assert c["counter_jumps"] == 3
    assert c["frames"] == 50 * 3 + 1 - 1 + 1
    assert c["decoded"] == c["frames"] - 3


def test_only_foreign_frames_is_no_hydraulic_data(tmp_path) -> None:
    log = tmp_path / "car.log"
    log.write_text("(1.000000) can0 123#0011\n(1.010000) can0 456#00\n")
    with pytest.raises(NoHydraulicDataError, match=r"car\.log: 2 frames read, none") as err:
        recording_from_candump(log)
    assert err.value.exit_code == 3


def test_only_rejected_hydraulic_frames_is_no_hydraulic_data(tmp_path) -> None:
    log = tmp_path / "bad.log"
    log.write_text("(1.000000) can0 0CFF1021#0000000000000000\n")  # CRC wrong
    with pytest.raises(NoHydraulicDataError, match="rejected: crc 1"):
        recording_from_candump(log)


@pytest.mark.skipif(not REAL_LOGS.is_dir(), reason=f"shared real CAN logs not at {REAL_LOGS}")
@pytest.mark.parametrize("name", GOOD_LOGS)
def test_real_car_logs_have_no_hydraulic_data(name: str) -> None:
    path = REAL_LOGS / name
    n = sum(1 for x in path.read_text().splitlines() if x.strip())
    with pytest.raises(NoHydraulicDataError, match=rf"{n} frames read, none of them") as err:
        recording_from_candump(path)
    assert name in str(err.value)


def test_codec_reused_between_logs_starts_fresh(tmp_path) -> None:
    codec = FrameCodec.from_dbc()
    write_candump(tmp_path / "a.log", make_recording(20))
    a = recording_from_candump(tmp_path / "a.log", codec)
    b = recording_from_candump(tmp_path / "a.log", codec)
    assert a.meta["counts"] == b.meta["counts"]
    assert b.meta["counts"]["counter_jumps"] == 0
    assert not math.isnan(b["PP"][0])


@pytest.mark.skipif(not REAL_LOGS.is_dir(), reason=f"shared real CAN logs not at {REAL_LOGS}")
@pytest.mark.parametrize(("name", "line"), [("civic8th_test.log", 1)])
def test_malformed_real_logs_are_file_errors_not_missing_data(name: str, line: int) -> None:
    with pytest.raises(InputFileError, match=rf"{name}:{line}: ") as err:
        recording_from_candump(REAL_LOGS / name)
    assert err.value.exit_code == 2
