"""The bulk offline path (candump text -> frames -> decoded values -> 100 Hz rows) against
python-can's reader, cantools' decoder and the frame-by-frame sampler."""

from __future__ import annotations

from pathlib import Path

import can
import cantools
import numpy as np
import pytest
from naive_frames import read_candump_lines, recording_from_candump
from shared_data import BAD_LOGS, GOOD_LOGS, REAL_LOGS, TORN_LOGS

from monitor.codec import FrameCodec
from monitor.codec.bulk import decode_frames, raw_values
from monitor.codec.layout import MessageInfo, message_info
from monitor.codec.logwrite import write_candump
from monitor.detection.offline import detect
from monitor.errors import InputFileError, NoHydraulicDataError
from monitor.io.candump import format_line, read_candump
from monitor.io.candump_bulk import read_candump_frames
from monitor.model.modelfile import load_model
from monitor.resources import resource_path
from monitor.sampling.bulk import recording_from_candump_bulk
from monitor.sim.cycles import make_cycle
from monitor.sim.faults import Fault
from monitor.sim.machine import load_machine
from monitor.sim.simulate import simulate

SHIPPED = [resource_path("replay", n) for n in ("normal.log", "spool_wear.log")]
needs_real = pytest.mark.skipif(not REAL_LOGS.is_dir(), reason=f"no real logs at {REAL_LOGS}")


def assert_same_frames(path: Path) -> None:
    got = read_candump_frames(path)
    with can.LogReader(str(path)) as reader:
        ref = list(reader)
    assert len(got) == len(ref)
    for i, m in enumerate(ref):
        assert got.timestamp[i] == m.timestamp  # bit for bit
        assert got.error[i] == m.is_error_frame and got.remote[i] == m.is_remote_frame
        if m.is_error_frame:
            continue
        assert (got.can_id[i], bool(got.extended[i])) == (m.arbitration_id, m.is_extended_id)
        data = b"" if m.is_remote_frame else bytes(m.data)
        assert bytes(got.data[i, : got.length[i]]) == data


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.name)
def test_same_frames_as_python_can_on_shipped_logs(path):
    assert_same_frames(path)


@needs_real
@pytest.mark.parametrize("name", GOOD_LOGS)
def test_same_frames_as_python_can_on_real_logs(name):
    assert_same_frames(REAL_LOGS / name)


@needs_real
@pytest.mark.parametrize(("name", "line"), BAD_LOGS)
def test_malformed_real_logs_name_the_same_line(name, line):
    with pytest.raises(InputFileError, match=rf"{name}:{line}: not a candump -L line"):
        read_candump_frames(REAL_LOGS / name)


@needs_real
@pytest.mark.parametrize(("name", "line"), TORN_LOGS)
def test_torn_real_log_gives_the_frames_before_the_tear(name, line):
    """Both readers stop at the torn line: every whole line before it, nothing else."""
    bulk = read_candump_frames(REAL_LOGS / name)
    slow = list(read_candump_lines(REAL_LOGS / name))
    assert len(bulk) == len(slow) == line - 1
    assert np.array_equal(bulk.timestamp, [m.timestamp for m in slow])


def test_line_variants_and_errors(tmp_path):
    log = tmp_path / "v.log"
    log.write_text(
        "(1.000000) can0 123#\n"  # no data
        "(1.100000) vcan0 1ABCDEF0#R\n"  # remote
        "(1.200000) can1 123#0011 T\n"  # direction flag
        "(1.300000) can0 123##1001122\n"  # CAN FD
        "\n"
        "(1.400000) can0 20000080#0000000000000000\n"  # error frame (error + bus-error flags)
        "(1.500000) can0 1aBcDeF0#a0B1\r\n"  # lower-case hex, CRLF
        "(1.600000)\tcan0 7FF#01\n"  # tab
    )
    assert_same_frames(log)
    # The messages of the one parser (replay's) are python-can's, line by line.
    fields = (
        "timestamp",
        "arbitration_id",
        "is_extended_id",
        "is_remote_frame",
        "is_error_frame",
        "is_fd",
        "bitrate_switch",
        "error_state_indicator",
    )
    got, ref = list(read_candump(log)), list(read_candump_lines(log))
    assert [[getattr(m, f) for f in fields] for m in got] == [
        [getattr(m, f) for f in fields] for m in ref
    ]
    assert [bytes(m.data or b"") for m in got] == [bytes(m.data or b"") for m in ref]
    bad = tmp_path / "bad.log"
    bad.write_text("(1.000000) can0 123#00\n(1.0) can0 123#ABC\n")
    with pytest.raises(InputFileError, match=r"bad\.log:2: not a candump -L line"):
        read_candump_frames(bad)
    with pytest.raises(InputFileError, match="nope.log"):
        read_candump_frames(tmp_path / "nope.log")


def test_timestamps_bit_identical_to_float(tmp_path):
    rng = np.random.default_rng(3)
    stamps = [
        f"{rng.integers(0, 10 ** int(rng.integers(1, 11)))}."
        f"{rng.integers(0, 10**6):0{int(rng.integers(1, 10))}d}"
        for _ in range(3000)
    ]
    # 2^53 and more digits (numpy's parse), in range (at most 1e11 s)
    stamps += [
        "9007199254.740993",
        "99999999999.999999",
        "1700000000.0000001234",
        "0.000001",
        "1700000000.000000",
        "00000000001700000000.5",
    ]
    log = tmp_path / "ts.log"
    log.write_text("".join(f"({s}) can0 123#00\n" for s in stamps))
    got = read_candump_frames(log).timestamp
    assert got.tolist() == [float(s) for s in stamps]


def test_values_equal_cantools_decode():
    codec = FrameCodec.from_dbc()
    frames = read_candump_frames(SHIPPED[1])
    decoded = decode_frames(codec, frames)
    db = codec.db
    for name, dm in decoded.items():
        if not dm.rows.size:
            continue
        for k in np.linspace(0, dm.rows.size - 1, 50).astype(int):
            row = dm.rows[k]
            ref = db.get_message_by_name(name).decode(bytes(frames.data[row, :8]))
            for sig, vals in dm.values.items():
                assert vals[k] == pytest.approx(ref[sig], rel=1e-12, abs=1e-12)


def test_bit_layouts_from_cantools_incl_big_endian_and_signed():
    msg = cantools.database.can.Message(
        frame_id=0x123,
        name="M",
        length=8,
        signals=[
            cantools.database.can.Signal("A", start=0, length=12, is_signed=True),
            cantools.database.can.Signal("B", start=12, length=20),
            cantools.database.can.Signal("C", start=39, length=10, byte_order="big_endian"),
            cantools.database.can.Signal(
                "D", start=45, length=6, byte_order="big_endian", is_signed=True
            ),
            cantools.database.can.Signal("AliveCounter", start=48, length=4),
            cantools.database.can.Signal("CRC8", start=56, length=8),
        ],
    )
    info: MessageInfo = message_info(msg)
    data = np.random.default_rng(0).integers(0, 256, (500, 8), dtype=np.uint8)
    raw = raw_values(info, data)
    for i in range(500):
        ref = msg.decode(bytes(data[i]), scaling=False, decode_choices=False)
        assert {s: int(raw[s][i]) for s in "ABCD"} == {s: ref[s] for s in "ABCD"}
        # The frame-by-frame decoder reads the same layout.
        b = bytes(data[i])
        little, big = int.from_bytes(b, "little"), int.from_bytes(b, "big")
        assert {s.name: s.raw(little, big) for s in info.signals} == {s: ref[s] for s in "ABCD"}


# --------------------------------------------------------------------------- recordings


def _rewrite(log: Path, edit) -> None:
    lines = log.read_text().splitlines(keepends=True)
    log.write_text("".join(edit(lines)))


def _troubled_log(tmp_path: Path, seconds: float = 90.0) -> Path:
    """A faulty simulated run with every kind of trouble a real log shows."""
    rec = simulate(
        make_cycle("boom", seconds, 7), load_machine(), [Fault("spool_wear", 0.8, 40.0)], seed=7
    )
    log = tmp_path / "trouble.log"
    write_candump(log, rec)

    def edit(lines):
        out = []
        for i, line in enumerate(lines):
            head, data = line.rstrip("\n").split("#")
            ts = float(head[1 : head.index(")")])
            rest = head[head.index(")") :]
            if i % 997 == 10:  # CRC mismatch
                data = f"{int(data[:2], 16) ^ 1:02X}" + data[2:]
            elif i % 1499 == 20:  # DLC 7
                data = data[:14]
            elif i % 1201 == 30 or (6000 <= i < 6040 and "0CFF1021" in head):
                continue  # a lost frame (counter jump); pressures stale for a while
            elif i == 9000:  # reordering jitter: 5 ms early
                head = f"({ts - 0.005:.6f}" + rest
            elif i == 12000:  # a stray frame from the past
                head = f"({ts - 3.0:.6f}" + rest
            elif 20000 <= i < 20010:  # the logger's clock was reset by an hour
                head = f"({ts - 3600.0:.6f}" + rest
            elif i == 24000:  # a forward gap of two minutes, then on
                out.append(f"({ts + 120.0:.6f}{rest}#{data}\n")
            elif i % 2111 == 40 and "0CFF1021" in head:  # PP raw 0xFFFF, CRC not updated
                data = "FFFF" + data[4:]  # the CRC check rejects it first, as on a bus
            out.append(f"{head}#{data}\n")
            if i == 15000:
                out.append("(1700000050.000000) can0 123#0011\n")  # foreign traffic
                out.append("(1700000050.000000) can0 0CFF1021#R\n")  # remote with a DBC id
                out.append("(1700000050.000000) can0 20000080#0000000000000000\n")  # error
        return out

    _rewrite(log, edit)
    return log


def _range_violation(log: Path) -> None:
    """A frame with a valid CRC and the next alive counter but PP raw 0xFFFF (655.35 bar >
    400): range rejection."""
    codec = FrameCodec.from_dbc()
    last = [x for x in log.read_text().splitlines() if " 0CFF1021#" in x][-1]
    counter = int(last.split("#")[1][12:14], 16) & 0x0F
    frame = bytearray(
        codec.encode("HYD_Pressures", {"PP": 100, "PA": 50, "PB": 10}, counter=counter + 1)
    )
    frame[0] = frame[1] = 0xFF
    from monitor.codec.crc import crc8_sae_j1850

    frame[7] = crc8_sae_j1850(frame[:7])
    with log.open("a") as fh:
        fh.write(f"(1700000095.000000) can0 0CFF1021#{frame.hex().upper()}\n")


def assert_same_recording(a, b) -> None:
    assert a.columns.keys() == b.columns.keys()
    np.testing.assert_array_equal(a.t, b.t)
    for name in b.columns:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    assert a.meta == b.meta
    assert a.source == b.source


@pytest.fixture(scope="module")
def troubled(tmp_path_factory):
    log = _troubled_log(tmp_path_factory.mktemp("bulk"))
    _range_violation(log)
    return log


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.name)
def test_same_recording_on_shipped_logs(path):
    assert_same_recording(recording_from_candump_bulk(path), recording_from_candump(path))


def test_same_recording_and_events_on_a_log_with_injected_trouble(troubled):
    bulk, ref = recording_from_candump_bulk(troubled), recording_from_candump(troubled)
    assert_same_recording(bulk, ref)
    c = bulk.meta["counts"]
    # The trouble is really there, so the equality above covers each rule.
    assert all(c["rejected"][k] > 0 for k in ("dlc", "crc", "range", "sequence"))
    assert c["counter_jumps"] > 0 and c["ignored"] == 2
    assert c["time_backwards"] > 0 and c["time_skipped"] >= 1
    assert c["time_resyncs"] >= 1 and c["gaps_shortened"] >= 1
    assert np.isnan(bulk["PP"]).any()
    model = load_model(resource_path("config", "boom_default.model.npz"))
    a, b = detect(model, bulk), detect(model, ref)
    assert a.events == b.events and a.summary == b.summary
    states = {e["state"] for e in a.events}
    assert {"fault", "sensor_fault", "inactive"} <= states


def test_no_hydraulic_data_and_rod_pos(tmp_path):
    car = tmp_path / "car.log"
    car.write_text("(1.000000) can0 123#0011\n(1.010000) can0 0CFF1021#0000000000000000\n")
    for fn in (recording_from_candump, recording_from_candump_bulk):
        with pytest.raises(NoHydraulicDataError, match=r"2 frames read, none.*crc 1"):
            fn(car)
    rec = simulate(make_cycle("boom", 5, 1), load_machine(), seed=1)
    log = tmp_path / "rod.log"
    write_candump(log, rec)
    assert "RodPos" in recording_from_candump_bulk(log).columns
    assert_same_recording(recording_from_candump_bulk(log), recording_from_candump(log))


def _with_outage(src: Path, dst: Path, cut_s: float, gap_s: float, drop: int | None = None):
    """``src`` with ``gap_s`` of silence inserted at ``cut_s`` of log time; frames of CAN id
    ``drop`` are left out after the cut (that sender does not come back)."""
    with dst.open("w") as fh:
        t0 = None
        for m in read_candump(src):
            t0 = m.timestamp if t0 is None else t0
            after = m.timestamp - t0 >= cut_s
            if after and m.arbitration_id == drop:
                continue
            shift = gap_s if after else 0.0
            fh.write(
                format_line(
                    m.timestamp + shift, "can0", m.arbitration_id, m.is_extended_id, bytes(m.data)
                )
            )
    return dst


def _first_row_back(rec) -> int:
    """The first row with PP again after the silence (PP is stale 30 ms into it)."""
    silent = np.flatnonzero(~np.isfinite(rec["PP"]))
    return int(silent[-1]) + 1


@pytest.mark.parametrize("gap_s", [0.5, 2.5, 5.0, 75.0])
def test_after_an_outage_a_slow_signal_is_fresh_until_its_next_frame(tmp_path, gap_s):
    """HYD_OilTemp comes once a second and is stale 3 s after its last frame.  After a
    silence of the whole bus it must not read as a failed sensor for the second until its
    next frame: staleness restarts at the first frame back (an outage is >= 1 s)."""
    log = _with_outage(resource_path("replay", "normal.log"), tmp_path / "o.log", 40.3, gap_s)
    bulk, ref = recording_from_candump_bulk(log), recording_from_candump(log)
    assert_same_recording(bulk, ref)
    back = _first_row_back(ref)
    silence = min(gap_s, 60.0)  # a gap over max_gap_s is shortened to it
    assert ref.t[back] == pytest.approx(40.3 + silence, abs=0.02)
    assert np.isfinite(ref["OilTemp"][back:]).all()


def test_after_an_outage_a_sender_that_stays_silent_is_stale_after_its_time(tmp_path):
    oil_id = FrameCodec.from_dbc().message("HYD_OilTemp").frame_id
    log = _with_outage(
        resource_path("replay", "normal.log"), tmp_path / "o.log", 40.3, 5.0, drop=oil_id
    )
    bulk, ref = recording_from_candump_bulk(log), recording_from_candump(log)
    assert_same_recording(bulk, ref)
    back = _first_row_back(ref)
    oil = np.isfinite(ref["OilTemp"])
    # Fresh for its 3 s staleness from the first frame back, then missing for good.
    assert oil[back : back + 299].all() and not oil[back + 301 :].any()
