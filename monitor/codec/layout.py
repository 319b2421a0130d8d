"""The message layout, derived once from the DBC via cantools: per message its id, cycle time
and physical signals, per signal where its bits are (start, length, byte order, sign),
its scaling and raw range; the alive counter and the CRC at fixed bytes.  Both decoders use
it: ``monitor.codec.frames`` frame by frame (live), ``monitor.codec.bulk`` over whole logs.

The frame rules of docs/reference/contracts.md: every frame is 8 bytes, byte 6 low nibble
is an alive counter (+1 mod 16 per frame of that message), byte 7 a CRC-8/SAE-J1850 over
bytes 0-6 (``monitor.codec.crc``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from cantools.database.can import Message as DbcMessage
from cantools.database.utils import start_bit

from monitor.errors import ConfigError

FRAME_LENGTH = 8
COUNTER_SIGNAL = "AliveCounter"
CRC_SIGNAL = "CRC8"
COUNTER_BYTE = 6  # low nibble
CRC_BYTE = 7
COUNTER_MODULO = 16


@dataclass(frozen=True)
class SignalInfo:
    """Where a signal's bits are, its scaling and the raw range that maps onto the DBC's
    [min, max].

    The raw value is ``(word >> shift) & mask`` with ``word`` the 8 data bytes read as one
    little-endian integer, or big-endian for a ``big_endian`` (Motorola) signal, then two's
    complement of ``length`` bits when ``signed``.
    """

    name: str
    scale: float
    offset: float
    raw_min: int
    raw_max: int
    phys_min: float  # on the quantisation grid, so a clipped value always re-decodes in range
    phys_max: float
    shift: int = 0
    length: int = 64
    signed: bool = False
    big_endian: bool = False

    @property
    def mask(self) -> int:
        return (1 << self.length) - 1

    def raw(self, little: int, big: int) -> int:
        """The raw value of one frame whose bytes read as ``little`` (little-endian) and
        ``big`` (big-endian) integers."""
        r = ((big if self.big_endian else little) >> self.shift) & self.mask
        if self.signed and r >> (self.length - 1):
            r -= 1 << self.length
        return r


@dataclass(frozen=True)
class MessageInfo:
    """What the codec precompiles for one DBC message."""

    name: str
    frame_id: int
    is_extended_id: bool
    cycle_time_s: float | None  # GenMsgCycleTime, None when the DBC gives none (or 0)
    signals: tuple[SignalInfo, ...]  # physical signals, without counter and CRC
    dbc_message: DbcMessage

    @property
    def signal_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.signals)


def signal_info(msg: DbcMessage, sig) -> SignalInfo:
    conv = sig.conversion
    scale = float(conv.scale)
    offset = float(conv.offset)
    if getattr(conv, "is_float", False) or scale == 0.0 or sig.multiplexer_ids:
        raise ConfigError(f"message {msg.name}: signal {sig.name} must be a plain integer signal")
    bit_min = -(1 << (sig.length - 1)) if sig.is_signed else 0
    bit_max = (1 << (sig.length - 1)) - 1 if sig.is_signed else (1 << sig.length) - 1
    lo_raw, hi_raw = bit_min, bit_max
    if sig.minimum is not None and sig.maximum is not None:
        a = (float(sig.minimum) - offset) / scale
        b = (float(sig.maximum) - offset) / scale
        lo, hi = min(a, b), max(a, b)
        # 1e-9 absorbs float noise such as (400 - 0) / 0.01 = 40000.000000000004
        lo_raw = max(bit_min, math.ceil(lo - 1e-9))
        hi_raw = min(bit_max, math.floor(hi + 1e-9))
    p1, p2 = lo_raw * scale + offset, hi_raw * scale + offset
    if sig.byte_order == "little_endian":
        shift, big = sig.start, False
    else:  # start_bit: the msb's position counted from byte 0's msb
        shift, big = 8 * FRAME_LENGTH - start_bit(sig) - sig.length, True
    return SignalInfo(
        sig.name,
        scale,
        offset,
        lo_raw,
        hi_raw,
        min(p1, p2),
        max(p1, p2),
        shift,
        sig.length,
        bool(sig.is_signed),
        big,
    )


def message_info(msg: DbcMessage) -> MessageInfo:
    if msg.length != FRAME_LENGTH or msg.is_multiplexed():
        raise ConfigError(f"message {msg.name}: must be a non-multiplexed 8-byte frame")
    by_name = {s.name: s for s in msg.signals}
    counter, crc_sig = by_name.get(COUNTER_SIGNAL), by_name.get(CRC_SIGNAL)
    # Counter and CRC are read from fixed bytes (the contract), so the DBC must agree.
    if (
        counter is None
        or crc_sig is None
        or (counter.start, counter.length, counter.byte_order) != (48, 4, "little_endian")
        or (crc_sig.start, crc_sig.length, crc_sig.byte_order) != (56, 8, "little_endian")
    ):
        raise ConfigError(
            f"message {msg.name}: needs {COUNTER_SIGNAL} at bit 48 (4 bits) and "
            f"{CRC_SIGNAL} at bit 56 (8 bits), little endian"
        )
    signals = tuple(
        signal_info(msg, s) for s in msg.signals if s.name not in (COUNTER_SIGNAL, CRC_SIGNAL)
    )
    cycle_ms = msg.cycle_time
    return MessageInfo(
        name=msg.name,
        frame_id=msg.frame_id,
        is_extended_id=bool(msg.is_extended_frame),
        cycle_time_s=cycle_ms / 1000.0 if cycle_ms else None,
        signals=signals,
        dbc_message=msg,
    )
