"""``FrameCodec.decode`` for a whole log at once, vectorised by message ID.

The checks and counts are those of ``FrameCodec.decode`` frame by frame, in the same order:
unknown id (ignored), DLC not 8, CRC-8 over bytes 0-6, raw value outside the DBC range,
the alive-counter rule (``monitor.codec.counter``, the same function; only frames that
passed CRC and range move the counter).  Bit positions, lengths, byte order, signedness,
scaling and raw ranges come from the message layout (``monitor.codec.layout``, read once
from the DBC with cantools) and the CRC from ``monitor.codec.crc``'s table, as in
``FrameCodec.decode``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.codec.counter import OUT_OF_SEQUENCE, counter_verdicts
from monitor.codec.crc import crc8_rows
from monitor.codec.frames import DecodeCounts, FrameCodec, Rejection
from monitor.codec.layout import (
    COUNTER_BYTE,
    COUNTER_MODULO,
    CRC_BYTE,
    FRAME_LENGTH,
    MessageInfo,
)
from monitor.io.candump_bulk import Frames


@dataclass
class DecodedMessage:
    """Accepted frames of one message: their row in the log and physical values."""

    rows: np.ndarray  # int64 indices into the log's frames, in order
    values: dict[str, np.ndarray]  # signal -> float64 per accepted frame


def raw_values(info: MessageInfo, data: np.ndarray) -> dict[str, np.ndarray]:
    """Raw integer of each physical signal of ``info`` in every row of 8-byte ``data`` (the
    bits where the layout says)."""
    b = np.ascontiguousarray(data[:, :FRAME_LENGTH])
    little = b.view("<u8").ravel()
    big = b.view(">u8").ravel()
    out = {}
    for sig in info.signals:
        word = big if sig.big_endian else little
        raw = ((word >> np.uint64(sig.shift)) & np.uint64(sig.mask)).astype(np.int64)
        if sig.signed:
            raw = np.where(raw >> (sig.length - 1) != 0, raw - (1 << sig.length), raw)
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
            ~frames.error
            & (frames.can_id == info.frame_id)
            & (frames.extended == info.is_extended_id)
        )
        known[rows] = True
        dlc_ok = (frames.length[rows] == FRAME_LENGTH) & ~frames.remote[rows]
        counts.reject(info.name, Rejection.DLC.value, int((~dlc_ok).sum()))
        rows = rows[dlc_ok]
        data = frames.data[rows, :FRAME_LENGTH]
        crc_ok = crc8_rows(data[:, :CRC_BYTE]) == data[:, CRC_BYTE]
        counts.reject(info.name, Rejection.CRC.value, int((~crc_ok).sum()))
        rows, data = rows[crc_ok], data[crc_ok]
        raw = raw_values(info, data)
        in_range = np.ones(rows.size, dtype=bool)
        for sig in info.signals:
            in_range &= (raw[sig.name] >= sig.raw_min) & (raw[sig.name] <= sig.raw_max)
        counts.reject(info.name, Rejection.RANGE.value, int((~in_range).sum()))
        rows, data = rows[in_range], data[in_range]
        raw = {k: v[in_range] for k, v in raw.items()}
        counter = (data[:, COUNTER_BYTE] & 0x0F).astype(np.int64)
        jumps = int(np.count_nonzero(counter[1:] != (counter[:-1] + 1) % COUNTER_MODULO))
        counts.counter_jumps += jumps
        counts.reject(info.name, "counter_jump", jumps)
        believed = counter_verdicts(counter) != OUT_OF_SEQUENCE
        counts.reject(info.name, Rejection.SEQUENCE.value, int((~believed).sum()))
        good = int(believed.sum())
        counts.decoded += good
        if good:
            counts.per_message[info.name] = good
        values = {
            sig.name: raw[sig.name][believed] * sig.scale + sig.offset for sig in info.signals
        }
        out[info.name] = DecodedMessage(rows[believed], values)
    counts.ignored = int(n - known.sum())
    return out
