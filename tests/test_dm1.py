"""J1939 DM1/DM2: byte layout against hand-computed J1939-73 bytes, framing against
python-can-j1939's receiver and cantools, and the sending schedule on a synthetic timeline
(the live path on a virtual bus is in test_dm1_live.py)."""

from __future__ import annotations

import math
from dataclasses import replace

import can
import numpy as np
import pytest
from cantools.j1939 import frame_id_unpack
from j1939_support import DM1_ID, TP_CM_ID, TP_DT_ID, decode_dm, dm_dbc, pgn_of, reassemble
from live_support import write_config

from monitor.codec.j1939.dtc import PGN_DM1, PGN_DM2, Dtc, Lamp, dm_payload, lamp_bytes
from monitor.codec.j1939.transport import frame_id, pgn_frames, requested_pgn
from monitor.config.settings import J1939Config, load_config
from monitor.detection.alarm import State
from monitor.errors import ConfigError
from monitor.live.dm1 import Diagnostics
from monitor.sampling.sampler import ROW_COLUMNS

SIGNALS = ("QP", "PP", "PA", "PB")  # the paper preset's model signals


# -- layout ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("spn", "fmi", "oc", "expected"),
    [
        # 520192 = 0x7F000 = 0b111 1111_0000 0000_0000: low byte 0x00, middle 0xF0, the top
        # three bits 0b111 above FMI 31 = 0b11111 -> 0xFF; CM 0 and OC 1 -> 0x01.
        (520192, 31, 1, bytes((0x00, 0xF0, 0xFF, 0x01))),
        # SPN 190 (engine speed) = 0xBE, FMI 2, never counted.
        (190, 2, 0, bytes((0xBE, 0x00, 0x02, 0x00))),
        # 0x5ABCD: 0xCD, 0xAB, top bits 0b101 << 5 | FMI 9 = 0xA0 | 0x09; OC 127 "n/a".
        (0x5ABCD, 9, 127, bytes((0xCD, 0xAB, 0xA9, 0x7F))),
        # The largest SPN, FMI 0: 0xFF 0xFF, 0b111 << 5 = 0xE0; OC 126 = 0x7E.
        (524287, 0, 126, bytes((0xFF, 0xFF, 0xE0, 0x7E))),
    ],
)
def test_dtc_bytes_by_hand_and_by_can_j1939(spn, fmi, oc, expected) -> None:
    packed = Dtc(spn, fmi, oc).pack()
    assert packed == expected
    lamps, dtcs = decode_dm(b"\x00\xff" + packed)
    assert dtcs == [(spn, fmi, oc)]


def test_lamp_bytes_by_hand() -> None:
    # Amber warning is bits 3-4 of byte 0: 0b0000_0100; not flashing: byte 1 all ones.
    assert lamp_bytes({Lamp("amber")}) == bytes((0x04, 0xFF))
    # Red stop (bits 5-6) and MIL (7-8) on: 0b0101_0000; flash: MIL slow 00, red fast 01,
    # amber and protect "do not flash" 11 -> 0b00_01_11_11.
    both = {Lamp("red", "fast"), Lamp("mil", "slow")}
    assert lamp_bytes(both) == bytes((0x50, 0x1F))
    lamps, _ = decode_dm(lamp_bytes(both) + Dtc(1, 1, 1).pack())
    assert lamps == {"protect": "off", "amber": "off", "red": "fast", "mil": "slow"}
    # The same lamp lit by two DTCs: the more urgent flash wins; "none" lights nothing.
    assert lamp_bytes({Lamp("amber"), Lamp("amber", "fast"), Lamp(None)}) == bytes((4, 0xF7))
    assert lamp_bytes(set()) == bytes((0x00, 0xFF))


def test_no_dtc_form_is_spn0_fmi0_padded() -> None:
    assert dm_payload(lamp_bytes(set()), []) == bytes((0, 0xFF, 0, 0, 0, 0, 0xFF, 0xFF))


def test_single_frame_dm1_decodes_with_the_dbc_and_cantools_ids() -> None:
    payload = dm_payload(lamp_bytes({Lamp("amber")}), [Dtc(520194, 7, 3)])
    (msg,) = pgn_frames(PGN_DM1, payload, 0xA0, 6)
    assert msg.arbitration_id == DM1_ID and msg.is_extended_id and len(msg.data) == 8
    fid = frame_id_unpack(msg.arbitration_id)
    assert (fid.priority, fid.source_address, pgn_of(msg.arbitration_id)) == (6, 0xA0, 65226)
    v = dm_dbc().decode_message(msg.arbitration_id, msg.data, decode_choices=False)
    assert v["SPN_High3"] * 65536 + v["SPN_Low16"] == 520194
    assert (v["FMI"], v["OccurrenceCount"], v["ConversionMethod"]) == (7, 3, 0)
    assert (v["AmberWarningLamp"], v["RedStopLamp"], v["FlashAmberWarningLamp"]) == (1, 0, 3)
    assert bytes(msg.data[6:]) == b"\xff\xff"  # 6 bytes of DM1, padded


@pytest.mark.parametrize("n_dtcs", [2, 3, 10])
def test_bam_frames_by_hand_and_reassembled_by_can_j1939(n_dtcs: int) -> None:
    dtcs = [Dtc(520192 + i, i % 32, i + 1) for i in range(n_dtcs)]
    payload = dm_payload(lamp_bytes({Lamp("red")}), dtcs)
    size = 2 + 4 * n_dtcs
    frames = pgn_frames(PGN_DM1, payload, 0xA0, 6)
    packets = math.ceil(size / 7)
    assert len(frames) == 1 + packets
    cm = frames[0]
    assert cm.arbitration_id == TP_CM_ID and pgn_of(cm.arbitration_id) == 60416
    # Control byte 32 (BAM), size LSB first, packet count, 0xFF, PGN 0x00FECA LSB first.
    assert bytes(cm.data) == bytes((32, size, 0, packets, 0xFF, 0xCA, 0xFE, 0x00))
    for seq, dt in enumerate(frames[1:], start=1):
        assert dt.arbitration_id == TP_DT_ID and pgn_of(dt.arbitration_id) == 60160
        chunk = payload[7 * (seq - 1) : 7 * seq]
        assert bytes(dt.data) == bytes((seq,)) + chunk + b"\xff" * (7 - len(chunk))
    for i, m in enumerate(frames):
        m.timestamp = 100.0 + 0.05 * i
    (group,) = reassemble(frames)
    assert (group["pgn"], group["sa"], group["data"]) == (PGN_DM1, 0xA0, payload)
    lamps, got = decode_dm(group["data"])
    assert got == [(d.spn, d.fmi, d.oc) for d in dtcs] and lamps["red"] == "on"


def _request(pgn: int, to: int, sa: int = 0xF9) -> can.Message:
    return can.Message(
        arbitration_id=frame_id(59904, sa, 6, destination=to), data=pgn.to_bytes(3, "little")
    )


def test_requests_for_us_or_for_all_only() -> None:
    assert _request(PGN_DM2, 0xA0).arbitration_id == 0x18EAA0F9
    assert requested_pgn(_request(PGN_DM2, 0xA0), 0xA0) == PGN_DM2
    assert requested_pgn(_request(PGN_DM1, 0xFF), 0xA0) == PGN_DM1
    assert requested_pgn(_request(PGN_DM2, 0x17), 0xA0) is None
    sensor = can.Message(arbitration_id=0x0CFF1021, data=bytes(8))
    assert requested_pgn(sensor, 0xA0) is None


# -- schedule ----------------------------------------------------------------------------


def _row(t: float, stale: tuple[str, ...] = ()) -> np.ndarray:
    row = np.ones(1 + len(ROW_COLUMNS))
    row[0] = t
    for s in stale:
        row[1 + ROW_COLUMNS.index(s)] = np.nan
    return row


Segment = tuple[float, State, str, tuple[str, ...]]


def _drive(diag: Diagnostics, segments: list[Segment], start: int = 0) -> list[can.Message]:
    """Ticks at 100 Hz through (duration s, state, fault, stale signals) segments; frames
    are stamped with their sample time."""
    out, k = [], start
    for duration, state, fault, stale in segments:
        for _ in range(round(duration / 0.01)):
            t = k * 0.01
            out += diag.tick(t, t, state, fault, _row(t, stale))
            k += 1
    return out


def _dm1s(frames: list[can.Message]) -> list[tuple[float, list[tuple[int, int, int]]]]:
    """(time, DTCs) of every DM1, single frame or BAM, as can-j1939 reads them."""
    return [
        (round(g["t"], 3), decode_dm(g["data"])[1])
        for g in reassemble(frames)
        if g["pgn"] == PGN_DM1
    ]


NO_DTC = [(0, 0, 0)]
WEAR = (520194, 7)


def test_dm1_on_change_and_every_second_while_active() -> None:
    diag = Diagnostics(J1939Config(enabled=True, repeat_when_clear=False), SIGNALS)
    frames = _drive(
        diag,
        [
            (2.0, State.NORMAL, "", ()),
            (3.5, State.FAULT, "spool_wear", ()),
            (2.0, State.NORMAL, "", ()),
            (1.0, State.FAULT, "spool_wear", ()),
        ],
    )
    got = _dm1s(frames)
    one = [(*WEAR, 1)]
    assert got == [
        (0.0, NO_DTC),  # the start announces "no DTC"
        (2.0, one),
        (3.0, one),
        (4.0, one),
        (5.0, one),  # fault at 2.0, every 1 s
        (5.5, NO_DTC),  # cleared: once, not repeated
        (7.5, [(*WEAR, 2)]),  # active again: the second occurrence
    ]
    assert all(m.arbitration_id == DM1_ID for m in frames)
    lamps, _ = decode_dm(bytes(frames[1].data))
    assert lamps == {"protect": "off", "amber": "on", "red": "off", "mil": "off"}
    assert decode_dm(bytes(frames[0].data))[0]["amber"] == "off"


def test_one_dtc_per_alarm_while_isolation_refines_its_answer() -> None:
    diag = Diagnostics(J1939Config(enabled=True, repeat_when_clear=False), SIGNALS)
    frames = _drive(
        diag,
        [
            (0.5, State.NORMAL, "", ()),
            (0.3, State.FAULT, "unknown", ()),  # not isolated yet
            (0.3, State.FAULT, "spool_wear", ()),
            (0.2, State.FAULT, "unknown", ()),  # a moment of doubt: keeps spool_wear
            (0.9, State.FAULT, "spool_wear", ()),
            (0.5, State.SENSOR_FAULT, "", ("QP",)),
            (0.2, State.FAULT, "spool_wear", ()),  # the same episode: not counted again
            (0.5, State.NORMAL, "", ()),
            (0.2, State.FAULT, "unknown", ()),  # a new alarm starts unnamed again
        ],
    )
    unknown, wear, qp = (520195, 11, 1), (*WEAR, 1), (520215, 9, 1)
    assert _dm1s(frames) == [
        (0.0, NO_DTC),
        (0.5, [unknown]),
        (0.8, [wear]),
        (1.8, [wear]),
        (2.2, [qp]),
        (2.7, [wear]),
        (2.9, NO_DTC),
        (3.4, [(520195, 11, 2)]),
    ]


def test_no_dtc_repeats_every_second_when_configured() -> None:
    diag = Diagnostics(J1939Config(enabled=True), SIGNALS)
    got = _dm1s(_drive(diag, [(2.5, State.NORMAL, "", ()), (1.2, State.FAULT, "x", ())]))
    unknown = (520195, 11, 1)  # a fault isolation could not name
    assert got == [(0.0, NO_DTC), (1.0, NO_DTC), (2.0, NO_DTC), (2.5, [unknown]), (3.5, [unknown])]


def test_sensor_fault_is_a_bam_per_stale_signal_kept_through_recovery() -> None:
    diag = Diagnostics(J1939Config(enabled=True, repeat_when_clear=False), SIGNALS)
    frames = _drive(
        diag,
        [
            (1.0, State.NORMAL, "", ()),
            (0.5, State.SENSOR_FAULT, "", ("PP", "PA", "PB")),
            (1.1, State.SENSOR_FAULT, "", ()),  # frames back, recovery debounce
            (1.0, State.NORMAL, "", ()),
        ],
    )
    cms = [m for m in frames if m.arbitration_id == TP_CM_ID]
    assert [m.timestamp for m in cms] == pytest.approx([1.0, 2.0])
    assert bytes(cms[0].data) == bytes((32, 14, 0, 2, 0xFF, 0xCA, 0xFE, 0))
    dts = [m.timestamp for m in frames if m.arbitration_id == TP_DT_ID]
    assert dts == pytest.approx([1.05, 1.10, 2.05, 2.10])  # J1939-21: 50-200 ms apart
    pressures = [(520212, 9, 1), (520213, 9, 1), (520214, 9, 1)]
    assert _dm1s(frames) == [(0.0, NO_DTC), (1.1, pressures), (2.1, pressures), (2.6, NO_DTC)]
    assert diag.previous == {(520212, 9), (520213, 9), (520214, 9)}


def test_sensor_fault_without_a_stale_signal_is_the_unknown_sensor_dtc() -> None:
    diag = Diagnostics(J1939Config(enabled=True, sensor_lamp="red:fast"), SIGNALS)
    frames = _drive(diag, [(0.2, State.SENSOR_FAULT, "", ())])
    lamps, dtcs = decode_dm(bytes(frames[0].data))
    assert dtcs == [(520223, 9, 1)] and lamps["red"] == "fast"


def test_sensor_named_by_a_plausibility_check_gets_its_spn_and_the_check_fmi() -> None:
    diag = Diagnostics(J1939Config(enabled=True, repeat_when_clear=False), SIGNALS)
    frames: list[can.Message] = []
    # PA reads above PP with the spool open (finite values, no stale signal): 0.5 s of the
    # finding, then 0.2 s of recovery debounce (finding gone, state still sensor fault).
    for k in range(100):
        t = k * 0.01
        state = State.NORMAL if k < 30 else State.SENSOR_FAULT if k < 100 else State.NORMAL
        named = ("PA", "pump_below_port") if 30 <= k < 80 else (None, None)
        frames += diag.tick(t, t, state, "", _row(t, ()), named)
    frames += diag.tick(1.0, 1.0, State.NORMAL, "", _row(1.0, ()))
    pa_offset = (520213, 13, 1)  # PA's SPN (520192 + 16 + 5), FMI 13 out of calibration
    assert _dm1s(frames) == [(0.0, NO_DTC), (0.3, [pa_offset]), (1.0, NO_DTC)]
    cfg = J1939Config(enabled=True, check_fmi={"pump_below_port": 3})
    assert cfg.check_fmi["pump_below_port"] == 3 and cfg.check_fmi["frozen"] == 10
    with pytest.raises(ConfigError, match="check_fmi.drift"):
        J1939Config(enabled=True, check_fmi={"drift": 3})


def test_silent_engine_speed_is_named_even_when_the_model_does_not_use_it() -> None:
    """HYD_Commands silent while the pump works: the gating names EngineSpeed ``stale``;
    the paper preset's model (QP, PP, PA, PB) has no stale signal of its own to name."""
    diag = Diagnostics(J1939Config(enabled=True, repeat_when_clear=False), SIGNALS)
    frames: list[can.Message] = []
    for k in range(100):
        t = k * 0.01
        state = State.NORMAL if k < 30 else State.SENSOR_FAULT if k < 90 else State.NORMAL
        silent = 30 <= k < 80  # then 0.1 s of recovery debounce, the commands back
        named = ("EngineSpeed", "stale") if silent else (None, None)
        stale = ("SpoolCmd", "PumpDispCmd", "EngineSpeed") if silent else ()
        frames += diag.tick(t, t, state, "", _row(t, stale), named)
    engine = (520210, 9, 1)  # EngineSpeed's SPN (520192 + 16 + 2), FMI 9 abnormal update rate
    assert _dm1s(frames) == [(0.0, NO_DTC), (0.3, [engine]), (0.9, NO_DTC)]


def test_dm2_and_dm1_answer_requests() -> None:
    diag = Diagnostics(J1939Config(enabled=True, repeat_when_clear=False), SIGNALS)
    before = _drive(diag, [(1.0, State.FAULT, "piston_wear", ()), (1.0, State.NORMAL, "", ())])
    assert diag.request(_request(PGN_DM2, 0xA0))
    assert not diag.request(_request(PGN_DM2, 0x17))  # for another ECU
    after = _drive(diag, [(0.3, State.NORMAL, "", ())], start=200)
    groups = reassemble(after)
    assert [g["pgn"] for g in groups] == [PGN_DM2]
    assert groups[0]["t"] == pytest.approx(2.0)  # at the next tick
    assert decode_dm(groups[0]["data"])[1] == [(520192, 7, 1)]  # previously active
    assert after[0].arbitration_id == 0x18FECBA0
    assert diag.request(_request(PGN_DM1, 0xFF))  # a global request for DM1
    again = _drive(diag, [(0.1, State.NORMAL, "", ())], start=230)
    assert _dm1s(again) == [(2.3, NO_DTC)]
    assert len(_dm1s(before)) == 2 and diag.counts()["j1939_requests"] == 2


def test_rate_cap_caps_a_flapping_state() -> None:
    cfg = J1939Config(enabled=True, max_frames_per_s=10.0)
    diag = Diagnostics(cfg, SIGNALS)
    # 5 s of fault and sensor fault (a 3-frame BAM) alternating every 10 ms.
    flap: list[Segment] = [
        (0.01, State.FAULT, "spool_wear", ()),
        (0.01, State.SENSOR_FAULT, "", ("PP", "PA")),
    ] * 250
    frames = _drive(diag, [*flap, (3.0, State.NORMAL, "", ())])
    t = np.array([m.timestamp for m in frames])
    # At most max_frames_per_s in any one-second window (a token bucket let twice that out).
    for start in t:
        assert np.sum((t >= start) & (t < start + 1.0)) <= cfg.max_frames_per_s
    assert np.sum(t < 5.0) <= cfg.max_frames_per_s * 5
    assert diag.held_back > 0
    assert _dm1s(frames)[-1][1] == NO_DTC  # the last word is the state that stayed


# -- config --------------------------------------------------------------------------------


def test_shipped_config_enables_dm1_with_proprietary_defaults() -> None:
    cfg = load_config().j1939
    assert cfg.enabled and cfg.source_address == 0xA0
    spns = [*cfg.fault_spn.values(), *cfg.sensor_spn.values()]
    assert all(520192 <= s <= 524287 for s in spns) and len(set(spns)) == len(spns)
    assert cfg == replace(J1939Config(), enabled=True)  # the YAML repeats the defaults


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        ("j1939:\n  fault_spn: {spool_wear: 600000}\n", "j1939.fault_spn.spool_wear must be"),
        ("j1939:\n  fault_spn: {wear: 1}\n", "unknown name j1939.fault_spn.wear"),
        ("j1939:\n  sensor_spn: {PP: 1.5}\n", "j1939.sensor_spn.PP must be a whole number"),
        ("j1939:\n  fault_fmi: {unknown: 32}\n", "j1939.fault_fmi.unknown must be"),
        ("j1939:\n  fault_lamp: blue\n", "j1939.fault_lamp must be none or one of"),
        ("j1939:\n  sensor_lamp: 'red:blink'\n", "j1939.sensor_lamp must be"),
        ("j1939:\n  bam_gap_s: 0.01\n", "j1939.bam_gap_s must be between 0.05 and 0.2"),
        ("j1939:\n  source_address: 255\n", "j1939.source_address must be 0..253"),
        ("j1939:\n  dm3: true\n", "unknown key j1939.dm3"),
    ],
)
def test_bad_j1939_config_is_one_clear_error(tmp_path, extra: str, message: str) -> None:
    with pytest.raises(ConfigError) as exc:
        load_config(write_config(tmp_path, extra))
    assert message in str(exc.value)
    assert str(exc.value).startswith(str(tmp_path / "monitor.yaml"))
    assert "\n" not in str(exc.value)


def test_a_partial_map_moves_single_numbers(tmp_path) -> None:
    cfg = load_config(write_config(tmp_path, "j1939:\n  sensor_spn: {OilTemp: 1638}\n")).j1939
    assert cfg.sensor_spn["OilTemp"] == 1638 and cfg.sensor_spn["PP"] == 520212
