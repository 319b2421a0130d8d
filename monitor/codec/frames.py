"""Per-frame work: physical signals <-> 8 data bytes with alive counter and CRC.

The frame rules (docs/reference/contracts.md) and where each signal's bits are: the
message layout (``monitor.codec.layout``), which the bulk decoder (``monitor.codec.bulk``)
reads too.
``FrameCodec`` precompiles what it needs per message once, so encode/decode only do
the per-frame arithmetic.  It never raises for bad bus data: a decode returns either
the physical values or a rejection reason.  Loading the DBC lives in ``monitor.codec.dbc``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import NamedTuple

import can
from cantools.database.can import Database

from monitor.codec.counter import BELIEVED, CounterState, counter_step, is_jump
from monitor.codec.crc import crc8_sae_j1850
from monitor.codec.dbc import load_dbc
from monitor.codec.layout import (
    COUNTER_BYTE,
    COUNTER_MODULO,
    COUNTER_SIGNAL,
    CRC_BYTE,
    CRC_SIGNAL,
    FRAME_LENGTH,
    MessageInfo,
    message_info,
)
from monitor.errors import ConfigError


class Rejection(str, Enum):
    """Why a frame was not accepted (the str value is what counts and logs show)."""

    DLC = "dlc"  # data length is not 8
    CRC = "crc"  # byte 7 does not match the CRC of bytes 0-6
    RANGE = "range"  # a signal decodes outside its DBC [min, max]
    SEQUENCE = "sequence"  # alive counter out of sequence (monitor.codec.counter)
    UNKNOWN_ID = "unknown_id"  # the frame is not in the DBC (foreign traffic)


class Decoded(NamedTuple):
    """Result of decoding one frame.

    ``values`` holds physical values (DBC units) when ``rejection`` is None.  ``name`` is
    the DBC message name (None for an unknown id).  ``counter_jump`` is set when the alive
    counter was not the previous frame's + 1 mod 16; one lost frame (+ 2) is still
    accepted, any other jump or a repeat is rejected (``Rejection.SEQUENCE``) until the
    message is back in sequence (``monitor.codec.counter``).
    """

    name: str | None
    values: dict[str, float] | None
    rejection: Rejection | None
    counter_jump: bool = False

    @property
    def ok(self) -> bool:
        return self.rejection is None


@dataclass
class DecodeCounts:
    """Frame counters of a decoder (per log offline, per session live)."""

    frames: int = 0
    decoded: int = 0
    ignored: int = 0  # unknown id: foreign traffic, not an error
    rejected: dict[str, int] = field(
        default_factory=lambda: {r.value: 0 for r in Rejection if r is not Rejection.UNKNOWN_ID}
    )
    counter_jumps: int = 0  # frames whose counter is not the previous frame's + 1
    per_message: dict[str, int] = field(default_factory=dict)  # decoded frames per message
    # message -> reason (dlc, crc, range, sequence, counter_jump) -> frames; only non-zero
    rejected_by_message: dict[str, dict[str, int]] = field(default_factory=dict)

    @property
    def rejected_total(self) -> int:
        return sum(self.rejected.values())

    def reject(self, message: str, reason: str, n: int = 1) -> None:
        """Count ``n`` frames of ``message`` rejected for ``reason`` (a counter jump is
        counted per message only: the frame itself may be accepted)."""
        if n <= 0:
            return
        if reason in self.rejected:
            self.rejected[reason] += n
        per = self.rejected_by_message.setdefault(message, {})
        per[reason] = per.get(reason, 0) + n

    def as_dict(self) -> dict[str, object]:
        return {
            "frames": self.frames,
            "decoded": self.decoded,
            "ignored": self.ignored,
            "rejected": dict(self.rejected),
            "counter_jumps": self.counter_jumps,
            "per_message": dict(self.per_message),
            "rejected_by_message": {k: dict(v) for k, v in self.rejected_by_message.items()},
        }


_FRESH = CounterState()


class FrameCodec:
    """Encode and check frames of one DBC; keeps alive-counter state per message.

    Transmit and receive counters are separate: ``encode`` numbers the frames it builds,
    ``decode`` checks the continuity of the frames it sees.
    """

    def __init__(self, db: Database) -> None:
        self.db = db
        self.messages: dict[str, MessageInfo] = {}
        self._by_id: dict[tuple[int, bool], MessageInfo] = {}
        for msg in db.messages:
            info = message_info(msg)
            self.messages[info.name] = info
            self._by_id[(info.frame_id, info.is_extended_id)] = info
        self._tx_counter: dict[str, int] = {}
        self._rx_counter: dict[str, CounterState] = {}
        self.counts = DecodeCounts()

    @classmethod
    def from_dbc(cls, path: str | Path | None = None) -> FrameCodec:
        """Codec of ``path`` (default: the shipped DBC)."""
        return cls(load_dbc(path))

    def message(self, name: str) -> MessageInfo:
        try:
            return self.messages[name]
        except KeyError:
            raise ConfigError(f"no message {name!r} in the DBC") from None

    def message_for_id(self, frame_id: int, is_extended_id: bool = True) -> MessageInfo | None:
        return self._by_id.get((frame_id, is_extended_id))

    def signal_cycle_times(self) -> dict[str, float]:
        """Cycle time (s) of the message carrying each physical signal."""
        return {
            s.name: info.cycle_time_s
            for info in self.messages.values()
            if info.cycle_time_s is not None
            for s in info.signals
        }

    def reset_counters(self) -> None:
        self._tx_counter.clear()
        self._rx_counter.clear()
        self.counts = DecodeCounts()

    # -- encoding ---------------------------------------------------------------------

    def encode(self, name: str, values: Mapping[str, float], counter: int | None = None) -> bytes:
        """8 data bytes of message ``name`` from physical ``values`` (DBC units).

        Values are clipped to the signal's DBC [min, max], as a saturated sensor reads,
        then quantised by cantools.  The alive counter is the message's next one unless
        ``counter`` is given.  A missing or NaN value is a ``ConfigError``: missing data
        is represented by not sending the frame.
        """
        info = self.message(name)
        phys: dict[str, float] = {}
        for sig in info.signals:
            try:
                v = float(values[sig.name])
            except KeyError:
                raise ConfigError(f"message {name}: no value for signal {sig.name}") from None
            if math.isnan(v):
                raise ConfigError(f"message {name}: signal {sig.name} is NaN (skip the frame)")
            phys[sig.name] = min(max(v, sig.phys_min), sig.phys_max)
        if counter is None:
            counter = self._tx_counter.get(name, -1) + 1
        counter %= COUNTER_MODULO
        self._tx_counter[name] = counter
        phys[COUNTER_SIGNAL] = counter
        phys[CRC_SIGNAL] = 0
        data = bytearray(info.dbc_message.encode(phys, scaling=True, padding=False, strict=False))
        data[CRC_BYTE] = crc8_sae_j1850(data[:CRC_BYTE])
        return bytes(data)

    def encode_message(
        self, name: str, values: Mapping[str, float], timestamp: float, counter: int | None = None
    ) -> can.Message:
        """A python-can ``Message`` of ``encode`` at ``timestamp`` (s)."""
        info = self.message(name)
        return can.Message(
            timestamp=timestamp,
            arbitration_id=info.frame_id,
            is_extended_id=info.is_extended_id,
            data=self.encode(name, values, counter),
            is_rx=False,
        )

    # -- decoding ---------------------------------------------------------------------

    def decode(
        self, frame_id: int, data: bytes | bytearray, is_extended_id: bool = True
    ) -> Decoded:
        """Check and decode one frame; never raises for bad bus data."""
        counts = self.counts
        counts.frames += 1
        info = self._by_id.get((frame_id, is_extended_id))
        if info is None:
            counts.ignored += 1
            return Decoded(None, None, Rejection.UNKNOWN_ID)
        name = info.name
        if len(data) != FRAME_LENGTH:
            counts.reject(name, Rejection.DLC.value)
            return Decoded(name, None, Rejection.DLC)
        if crc8_sae_j1850(data[:CRC_BYTE]) != data[CRC_BYTE]:
            counts.reject(name, Rejection.CRC.value)
            return Decoded(name, None, Rejection.CRC)
        little, big = int.from_bytes(data, "little"), int.from_bytes(data, "big")
        values: dict[str, float] = {}
        for sig in info.signals:
            r = sig.raw(little, big)
            if r < sig.raw_min or r > sig.raw_max:
                counts.reject(name, Rejection.RANGE.value)
                return Decoded(name, None, Rejection.RANGE)
            values[sig.name] = r * sig.scale + sig.offset
        # Only a frame that passed CRC and range moves the counter state: a corrupt or
        # forged frame caught by them must not shift the sequence the sender's frames keep.
        counter = data[COUNTER_BYTE] & 0x0F
        state = self._rx_counter.get(name, _FRESH)
        jump = is_jump(state, counter)
        verdict, self._rx_counter[name] = counter_step(state, counter)
        if jump:
            counts.counter_jumps += 1
            counts.reject(name, "counter_jump")
        if verdict not in BELIEVED:
            counts.reject(name, Rejection.SEQUENCE.value)
            return Decoded(name, None, Rejection.SEQUENCE, jump)
        counts.decoded += 1
        counts.per_message[name] = counts.per_message.get(name, 0) + 1
        return Decoded(name, values, None, jump)

    def decode_message(self, msg: can.Message) -> Decoded:
        """``decode`` for a python-can message; error and remote frames count as rejected
        (dlc) when they carry a DBC id, and as ignored otherwise."""
        if msg.is_error_frame:
            self.counts.frames += 1
            self.counts.ignored += 1
            return Decoded(None, None, Rejection.UNKNOWN_ID)
        data = b"" if msg.is_remote_frame else msg.data
        return self.decode(msg.arbitration_id, data, msg.is_extended_id)
