"""``FrameCodec.decode`` for a whole log at once, vectorised by message ID.

The checks and counts are those of ``FrameCodec.decode`` frame by frame, in the same order:
unknown id (ignored), DLC not 8, CRC-8 over bytes 0-6, alive counter continuity (counted,
the frame kept; only frames with a good CRC move the counter), raw value outside the DBC
range.  Bit positions, lengths, byte order and signedness come from cantools' signal
objects (``cantools.database.utils.start_bit`` for big-endian signals); scaling and raw
ranges from the codec's ``SignalInfo``, so both paths share one reading of the DBC.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from cantools.database.utils import start_bit

from monitor.codec.crc import _INIT, _TABLE, _XOROUT
from monitor.codec.frames import (
    COUNTER_BYTE,
    COUNTER_MODULO,
    CRC_BYTE,
    FRAME_LENGTH,
    DecodeCounts,
    FrameCodec,
    MessageInfo,
    Rejection,
)
from monitor.io.candump_bulk import Frames

_CRC_TABLE = np.frombuffer(_TABLE, dtype=np.uint8)


@dataclass
class DecodedMessage:
    """Accepted frames of one message: their row in the log and physical values."""

    rows: np.ndarray  # int64 indices into the log's frames, in order
    values: dict[str, np.ndarray]  # signal -> float64 per accepted frame


def crc8_rows(data: np.ndarray) -> np.ndarray:
    """CRC-8/SAE-J1850 of bytes 0-6 of every row (the table of ``monitor.codec.crc``)."""
    reg = np.full(data.shape[0], _INIT, dtype=np.uint8)
    for b in range(CRC_BYTE):
        reg = _CRC_TABLE[reg ^ data[:, b]]
    return reg ^ np.uint8(_XOROUT)


def raw_values(info: MessageInfo, data: np.ndarray) -> dict[str, np.ndarray]:
    """Raw integer of each physical signal of ``info`` in every row of 8-byte ``data``."""
    b = np.ascontiguousarray(data[:, :FRAME_LENGTH])
    little = b.view("<u8").ravel()
    big = b.view(">u8").ravel()
    by_name = {s.name: s for s in info.dbc_message.signals}
    out = {}
    for sig in info.signals:
        s = by_name[sig.name]
        mask = np.uint64((1 << s.length) - 1)
        if s.byte_order == "little_endian":
            raw = (little >> np.uint64(s.start)) & mask
        else:  # start_bit: the msb's position counted from byte 0's msb
            raw = (big >> np.uint64(64 - start_bit(s) - s.length)) & mask
        raw = raw.astype(np.int64)
        if s.is_signed:
            half = 1 << (s.length - 1)
            raw = np.where(raw >= half, raw - (1 << s.length), raw)
        out[sig.name] = raw
    return out


def decode_frames(codec: FrameCodec, frames: Frames) -> dict[str, DecodedMessage]:
    """Decode every frame of the codec's DBC; counts go to ``codec.counts`` as if each
    frame had gone through ``codec.decode_message`` (counters start fresh)."""
    codec.reset_counters()
    counts: DecodeCounts = codec.counts
    n = len(frames)
    counts.frames = n
    known = np.zeros(n, dtype=bool)
    out: dict[str, DecodedMessage] = {}
    for info in codec.messages.values():
        rows = np.flatnonzero(
            ~frames.error & (frames.can_id == info.frame_id)
            & (frames.extended == info.is_extended_id)
        )  # fmt: skip
        known[rows] = True
        dlc_ok = (frames.length[rows] == FRAME_LENGTH) & ~frames.remote[rows]
        counts.reject(info.name, Rejection.DLC.value, int((~dlc_ok).sum()))
        rows = rows[dlc_ok]
        data = frames.data[rows, :FRAME_LENGTH]
        crc_ok = crc8_rows(data) == data[:, CRC_BYTE]
        counts.reject(info.name, Rejection.CRC.value, int((~crc_ok).sum()))
        rows, data = rows[crc_ok], data[crc_ok]
        counter = (data[:, COUNTER_BYTE] & 0x0F).astype(np.int64)
        jumps = int(np.count_nonzero(counter[1:] != (counter[:-1] + 1) % COUNTER_MODULO))
        counts.counter_jumps += jumps
        counts.reject(info.name, "counter_jump", jumps)
        raw = raw_values(info, data)
        in_range = np.ones(rows.size, dtype=bool)
        for sig in info.signals:
            in_range &= (raw[sig.name] >= sig.raw_min) & (raw[sig.name] <= sig.raw_max)
        counts.reject(info.name, Rejection.RANGE.value, int((~in_range).sum()))
        good = int(in_range.sum())
        counts.decoded += good
        if good:
            counts.per_message[info.name] = good
        values = {
            sig.name: raw[sig.name][in_range] * sig.scale + sig.offset for sig in info.signals
        }
        out[info.name] = DecodedMessage(rows[in_range], values)
    counts.ignored = int(n - known.sum())
    return out
