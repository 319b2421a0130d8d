"""J1939-21 framing: 29-bit IDs, single frames, BAM (broadcast announce) and requests.

A parameter group of up to 8 bytes is one frame, padded with 0xFF.  A longer one goes out
as a BAM to the global address: TP.CM (PGN 60416, control byte 32 with the size, the
packet count and the PGN) and then one TP.DT (PGN 60160) per 7 bytes, numbered from 1,
the last padded with 0xFF; a sender leaves 50 to 200 ms between the packets.
The IDs come from cantools' J1939 helpers.
"""

from __future__ import annotations

import can
from cantools.j1939 import frame_id_pack

PGN_REQUEST = 59904  # 0xEA00
PGN_TP_CM = 60416  # 0xEC00
PGN_TP_DT = 60160  # 0xEB00
TP_CM_BAM = 32
TP_PRIORITY = 7  # J1939-21 default priority of TP.CM and TP.DT
GLOBAL = 0xFF
MAX_BAM_BYTES = 1785  # 255 packets of 7 bytes


def frame_id(pgn: int, source_address: int, priority: int, destination: int = GLOBAL) -> int:
    """The 29-bit ID of ``pgn``; PDU1 PGNs (PF < 240) carry ``destination`` in PS."""
    pf, ps = (pgn >> 8) & 0xFF, pgn & 0xFF
    if pf < 240:
        ps = destination
    return frame_id_pack(priority, 0, (pgn >> 16) & 1, pf, ps, source_address)


def _frame(arbitration_id: int, data: bytes) -> can.Message:
    return can.Message(arbitration_id=arbitration_id, is_extended_id=True, data=data)


def n_packets(size: int) -> int:
    return -(-size // 7)


def pgn_frames(pgn: int, payload: bytes, source_address: int, priority: int) -> list[can.Message]:
    """The frames of one parameter group, in sending order (BAM when over 8 bytes).

    Timestamps are left to the sender, which spaces the BAM's TP.DT packets."""
    if len(payload) <= 8:
        return [_frame(frame_id(pgn, source_address, priority), payload.ljust(8, b"\xff"))]
    size = len(payload)
    if size > MAX_BAM_BYTES:
        raise ValueError(f"a BAM carries at most {MAX_BAM_BYTES} bytes, got {size}")
    count = n_packets(size)
    cm = bytes((TP_CM_BAM, size & 0xFF, size >> 8, count, 0xFF)) + pgn.to_bytes(3, "little")
    out = [_frame(frame_id(PGN_TP_CM, source_address, TP_PRIORITY), cm)]
    dt_id = frame_id(PGN_TP_DT, source_address, TP_PRIORITY)
    for seq in range(1, count + 1):
        chunk = payload[7 * (seq - 1) : 7 * seq]
        out.append(_frame(dt_id, bytes((seq,)) + chunk.ljust(7, b"\xff")))
    return out


#: python-can filter passing requests (PGN 59904) from any address to any address.
REQUEST_FILTER = {"can_id": PGN_REQUEST << 8, "can_mask": 0xFF << 16, "extended": True}


def requested_pgn(msg: can.Message, source_address: int) -> int | None:
    """The PGN a request frame asks of us (sent to our address or to all), else None."""
    aid = msg.arbitration_id
    # Bit tests, not a full unpack: this sees every frame the monitor receives.
    if not msg.is_extended_id or (aid >> 16) & 0x3FF != PGN_REQUEST >> 8 or len(msg.data) < 3:
        return None
    if (aid >> 8) & 0xFF not in (source_address, GLOBAL):
        return None
    return int.from_bytes(bytes(msg.data[:3]), "little")
