"""Codec: CRC-8/SAE-J1850, DBC loading, frame encode/decode with counter, CRC and range checks."""

from __future__ import annotations

import os
import random

import numpy as np
import pytest
from naive import crc8_bitwise

from monitor.codec import FrameCodec, Rejection, crc8_sae_j1850, load_dbc
from monitor.codec.crc import CHECK_VALUE, reference_calculator
from monitor.errors import ConfigError

PRESSURES_ID = 0x0CFF1021  # 2365526049 in the DBC, with the extended-frame bit 31 cleared
COMMANDS_ID = 0x0CFF1203
OILTEMP_ID = 0x18FF1300


@pytest.fixture
def codec() -> FrameCodec:
    return FrameCodec.from_dbc()


def test_crc_check_value() -> None:
    # The catalogue check value of CRC-8/SAE-J1850 (reveng) is 0x4B.
    assert crc8_sae_j1850(b"123456789") == 0x4B
    assert reference_calculator().checksum(b"123456789") == 0x4B
    assert crc8_bitwise(b"123456789") == 0x4B == CHECK_VALUE


def test_crc_matches_library_and_bitwise_on_random_data() -> None:
    calc = reference_calculator()
    rnd = random.Random(1)
    for _ in range(500):
        data = bytes(rnd.randrange(256) for _ in range(7))
        assert crc8_sae_j1850(data) == calc.checksum(data) == crc8_bitwise(data)


def _hand_frame(payload6: bytes, counter: int) -> bytes:
    body = payload6 + bytes([counter & 0x0F])
    return body + bytes([crc8_bitwise(body)])


def test_hand_built_pressures_frame_decodes(codec: FrameCodec) -> None:
    # PP 123.45 bar -> raw 12345 = 0x3039 -> 39 30; PA 0 -> 00 00; PB 250 bar -> 25000 = 0x61A8.
    frame = _hand_frame(bytes([0x39, 0x30, 0x00, 0x00, 0xA8, 0x61]), counter=5)
    d = codec.decode(PRESSURES_ID, frame)
    assert d.ok and d.name == "HYD_Pressures" and not d.counter_jump
    assert d.values == pytest.approx({"PP": 123.45, "PA": 0.0, "PB": 250.0}, abs=1e-9)
    # and the encoder builds exactly these bytes
    assert codec.encode("HYD_Pressures", {"PP": 123.45, "PA": 0, "PB": 250}, counter=5) == frame


def test_hand_built_signed_and_offset_signals(codec: FrameCodec) -> None:
    # SpoolCmd -12.34 % -> raw -1234 = 0xFB2E; PumpDispCmd 100 % -> 10000 = 0x2710;
    # EngineSpeed 2200 rpm / 0.125 = 17600 = 0x44C0.
    frame = _hand_frame(bytes([0x2E, 0xFB, 0x10, 0x27, 0xC0, 0x44]), counter=15)
    d = codec.decode(COMMANDS_ID, frame)
    assert d.values == pytest.approx(
        {"SpoolCmd": -12.34, "PumpDispCmd": 100.0, "EngineSpeed": 2200.0}, abs=1e-9
    )
    # OilTemp 50 degC -> (50 + 273) / 0.03125 = 10336 = 0x2860.
    frame = _hand_frame(bytes([0x60, 0x28, 0, 0, 0, 0]), counter=0)
    assert codec.decode(OILTEMP_ID, frame).values == pytest.approx({"OilTemp": 50.0})


def test_encode_clips_to_dbc_range_and_quantises(codec: FrameCodec) -> None:
    data = codec.encode("HYD_Pressures", {"PP": 450.0, "PA": -2.0, "PB": 12.3449})
    d = codec.decode(PRESSURES_ID, data)
    assert d.ok
    assert d.values == pytest.approx({"PP": 400.0, "PA": 0.0, "PB": 12.34}, abs=1e-9)
    cmd = codec.encode("HYD_Commands", {"SpoolCmd": -150, "PumpDispCmd": 120, "EngineSpeed": 9e9})
    assert codec.decode(COMMANDS_ID, cmd).values == pytest.approx(
        {"SpoolCmd": -100.0, "PumpDispCmd": 100.0, "EngineSpeed": 3000.0}
    )


def test_encode_rejects_nan_and_missing_signal(codec: FrameCodec) -> None:
    with pytest.raises(ConfigError, match="PA"):
        codec.encode("HYD_Pressures", {"PP": 1.0, "PA": float("nan"), "PB": 1.0})
    with pytest.raises(ConfigError, match="PB"):
        codec.encode("HYD_Pressures", {"PP": 1.0, "PA": 1.0})
    with pytest.raises(ConfigError, match="NoSuch"):
        codec.encode("NoSuch", {})


def test_encode_counter_and_crc_bytes(codec: FrameCodec) -> None:
    counters = []
    for _ in range(40):
        data = codec.encode("HYD_Flow", {"QP": 12.5})
        assert len(data) == 8
        assert data[7] == crc8_bitwise(data[:7])
        assert data[6] >> 4 == 0  # high nibble unused
        counters.append(data[6] & 0x0F)
    assert counters == [i % 16 for i in range(40)]


def test_cantools_decodes_our_frames(codec: FrameCodec) -> None:
    db = load_dbc()
    data = codec.encode("HYD_Commands", {"SpoolCmd": 55.55, "PumpDispCmd": 80, "EngineSpeed": 1800})
    out = db.decode_message(COMMANDS_ID, data)
    assert out["SpoolCmd"] == pytest.approx(55.55)
    assert out["EngineSpeed"] == pytest.approx(1800)
    assert out["CRC8"] == data[7]


def test_rejections_and_counts(codec: FrameCodec) -> None:
    good = codec.encode("HYD_Pressures", {"PP": 1, "PA": 2, "PB": 3}, counter=0)
    assert codec.decode(PRESSURES_ID, good[:7]).rejection is Rejection.DLC
    assert codec.decode(PRESSURES_ID, good + b"\x00").rejection is Rejection.DLC
    bad_crc = good[:7] + bytes([good[7] ^ 0x01])
    assert codec.decode(PRESSURES_ID, bad_crc).rejection is Rejection.CRC
    # PP raw 0xFFFF = 655.35 bar > 400 bar, with a valid CRC: out of range.
    out_of_range = _hand_frame(bytes([0xFF, 0xFF, 0, 0, 0, 0]), counter=1)
    d = codec.decode(PRESSURES_ID, out_of_range)
    assert d.rejection is Rejection.RANGE and d.name == "HYD_Pressures"
    assert codec.decode(0x123, bytes(8), is_extended_id=False).rejection is Rejection.UNKNOWN_ID
    # the same number as a standard id is another frame
    assert codec.decode(PRESSURES_ID & 0x7FF, good, is_extended_id=False).rejection is (
        Rejection.UNKNOWN_ID
    )
    c = codec.counts
    assert c.frames == 6 and c.ignored == 2 and c.decoded == 0
    assert c.rejected == {"dlc": 2, "crc": 1, "range": 1, "sequence": 0}
    assert c.rejected_total == 4


def test_one_lost_frame_is_tolerated_a_larger_jump_rejected_until_three_in_sequence(
    codec: FrameCodec,
) -> None:
    frames = [codec.encode("HYD_Flow", {"QP": 1.0}) for _ in range(40)]  # counters 0..15, 0..

    def verdict(i: int) -> tuple[Rejection | None, bool]:
        d = codec.decode(0x0CFF1121, frames[i])
        return d.rejection, d.counter_jump

    assert [verdict(i) for i in range(3)] == [(None, False)] * 3  # counters 0, 1, 2
    assert verdict(4) == (None, True)  # 2 -> 4: one frame lost, believed
    # 4 -> 9: four lost (or a forged frame): rejected, and so are the next frames until
    # three in a row are in sequence (9, 10, 11): the third is the first believed again.
    assert verdict(9) == (Rejection.SEQUENCE, True)
    assert verdict(10) == (Rejection.SEQUENCE, False)
    assert verdict(11) == (None, False)  # resynchronised: no believed frame before it
    assert verdict(11) == (Rejection.SEQUENCE, True)  # so a repeat is not believed
    assert verdict(12) == (None, False)
    # wrap 15 -> 0 is continuous
    assert [verdict(i) for i in range(13, 20)] == [(None, False)] * 7
    # A repeat after two believed in sequence takes the last one's place (one of the two
    # was an intruder's, and the later one is kept), and the sender goes on.
    assert verdict(19) == (None, True)
    assert verdict(20) == (None, False)
    c = codec.counts
    assert c.counter_jumps == 4 and c.rejected["sequence"] == 3
    assert c.rejected_by_message == {"HYD_Flow": {"counter_jump": 4, "sequence": 3}}
    # a corrupt frame does not move the counter state
    bad = frames[21][:7] + bytes([frames[21][7] ^ 0xFF])
    assert codec.decode(0x0CFF1121, bad).rejection is Rejection.CRC
    assert verdict(21) == (None, False)  # the last good one was 20 (counter 4)


def test_a_forged_frame_between_the_senders_changes_nothing(codec: FrameCodec) -> None:
    frames = [codec.encode("HYD_Flow", {"QP": 1.0}) for _ in range(10)]
    forged = codec.encode("HYD_Flow", {"QP": 99.0}, counter=12)
    seen = []
    for f in frames[:5]:
        seen.append(codec.decode(0x0CFF1121, f))
    seen.append(codec.decode(0x0CFF1121, forged))  # 4 -> 12
    for f in frames[5:]:
        seen.append(codec.decode(0x0CFF1121, f))  # 12 -> 5 jumps back, yet in sequence
    assert [d.rejection for d in seen] == [None] * 5 + [Rejection.SEQUENCE] + [None] * 5
    assert all(d.values == {"QP": 1.0} for d in seen if d.ok)
    # A forged frame with the sender's next number is believed (no receiver can tell),
    # but the sender's frame right after it takes its place: nothing of it outlives that.
    before = codec.encode("HYD_Flow", {"QP": 1.0}, counter=10)
    fake = codec.encode("HYD_Flow", {"QP": 55.0}, counter=11)
    own = codec.encode("HYD_Flow", {"QP": 1.0}, counter=11)
    then = codec.encode("HYD_Flow", {"QP": 1.0}, counter=12)
    got = [codec.decode(0x0CFF1121, f).values for f in (before, fake, own, then)]
    assert got == [{"QP": 1.0}, {"QP": 55.0}, {"QP": 1.0}, {"QP": 1.0}]


@pytest.mark.parametrize("seed", range(6))
def test_counter_rule_of_both_decoders_matches_the_reference(seed: int) -> None:
    """``counter_verdicts`` (the bulk decoder's) and ``FrameCodec.decode`` frame by frame
    believe exactly the frames the plain reference in tests/naive_frames.py believes, on
    counter sequences with losses, repeats, restarts and random frames."""
    from naive_frames import counter_believed

    from monitor.codec.counter import OUT_OF_SEQUENCE, counter_verdicts

    rnd = random.Random(seed)
    counters, c = [], rnd.randrange(16)
    for _ in range(3000):
        r = rnd.random()
        c = (c + 1) % 16 if r < 0.8 else (c + 2) % 16 if r < 0.85 else rnd.randrange(16)
        counters.append(c)
    expected = counter_believed(counters)
    assert (counter_verdicts(np.array(counters)) != OUT_OF_SEQUENCE).tolist() == expected
    codec = FrameCodec.from_dbc()
    live = [
        codec.decode(0x0CFF1121, codec.encode("HYD_Flow", {"QP": 1.0}, counter=k)).ok
        for k in counters
    ]
    assert live == expected
    assert 100 < expected.count(False) < 1000  # the sequences do exercise the rule


def test_counters_are_per_message(codec: FrameCodec) -> None:
    for i in range(5):
        p = codec.encode("HYD_Pressures", {"PP": 1, "PA": 1, "PB": 1})
        f = codec.encode("HYD_Flow", {"QP": 1})
        assert p[6] == f[6] == i
        assert not codec.decode(PRESSURES_ID, p).counter_jump
        assert not codec.decode(0x0CFF1121, f).counter_jump


def test_decode_never_raises_on_garbage(codec: FrameCodec) -> None:
    rnd = random.Random(7)
    ids = [m.frame_id for m in codec.messages.values()] + [0x100, 0x1FFFFFFF]
    for _ in range(2000):
        data = os.urandom(rnd.choice([0, 1, 7, 8, 8, 8, 12, 64]))
        d = codec.decode(rnd.choice(ids), data, is_extended_id=rnd.random() < 0.8)
        assert d.ok or isinstance(d.rejection, Rejection)


def test_load_dbc_errors_name_the_file(tmp_path) -> None:
    missing = tmp_path / "nope.dbc"
    with pytest.raises(ConfigError, match="nope.dbc"):
        load_dbc(missing)
    broken = tmp_path / "broken.dbc"
    broken.write_text(
        'VERSION ""\nBO_ 1 X: 8 N\n SG_ A : 0|16@1+ (1,0) [0|1] "" N\n'
        ' SG_ B : 8|16@1+ (1,0) [0|1] "" N\n'
    )  # overlapping signals
    with pytest.raises(ConfigError, match="broken.dbc"):
        load_dbc(broken)


def test_shipped_dbc_messages(codec: FrameCodec) -> None:
    names = set(codec.messages)
    assert {
        "HYD_Pressures",
        "HYD_Flow",
        "HYD_RodPos",
        "HYD_Commands",
        "HYD_OilTemp",
        "MON_Alarm",
        "MON_Status",
    } <= names
    cycles = codec.signal_cycle_times()
    assert cycles["PP"] == 0.01 and cycles["OilTemp"] == 1.0
