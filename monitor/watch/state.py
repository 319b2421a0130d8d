"""What `monitor watch` knows, from the bus alone: the monitor's own frames and the sensors'.

Fed one frame at a time (``feed``), it keeps per loop the latest MON_Alarm (state, J,
threshold, fault, alarm count), the latest MON_Status (state, operating state, range and
sensor-check flags, frame counters, bus events), the active DTCs of each DM1 sender (single
frame or J1939-21 BAM, reassembled here), and the latest decoded sensor values with frame
and reject counts per message.  It never talks on the bus, so it can sit beside a running
daemon on the machine.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import can

from monitor.codec.frames import FrameCodec
from monitor.codec.j1939.transport import PGN_TP_CM, PGN_TP_DT, TP_CM_BAM

PGN_DM1 = 65226  # 0xFECA
SENSORS = ("PP", "PA", "PB", "QP")


@dataclass
class AlarmView:
    state: str = "?"
    j: float | None = None
    threshold: float | None = None
    fault: str = "none"
    alarms: int = 0
    seen_mono: float = 0.0

    @property
    def ratio(self) -> float | None:
        """J / eps0, the share of the threshold J has reached."""
        if self.j is None or not self.threshold:
            return None
        return self.j / self.threshold


@dataclass
class DtcView:
    spn: int
    fmi: int
    oc: int


@dataclass
class WatchState:
    codec: FrameCodec
    alarms: dict[str, AlarmView] = field(default_factory=dict)  # message name -> latest
    status: dict[str, object] = field(default_factory=dict)
    status_mono: float = 0.0
    dm1: dict[int, tuple[list[str], list[DtcView]]] = field(default_factory=dict)  # SA ->
    values: dict[str, float] = field(default_factory=dict)
    frames: dict[str, int] = field(default_factory=dict)  # per message, decoded
    rejected: dict[str, int] = field(default_factory=dict)  # per message, any reason
    total: int = 0
    _bam: dict[int, tuple[int, int, bytearray]] = field(default_factory=dict)  # SA ->

    def feed(self, msg: can.Message, now_mono: float | None = None) -> None:
        now = time.monotonic() if now_mono is None else now_mono
        self.total += 1
        if msg.is_error_frame or msg.is_remote_frame:
            return
        if msg.is_extended_id and self._j1939(msg):
            return
        d = self.codec.decode_message(msg)
        if d.name is None:
            return
        if d.rejection is not None:
            self.rejected[d.name] = self.rejected.get(d.name, 0) + 1
            return
        self.frames[d.name] = self.frames.get(d.name, 0) + 1
        values = d.values or {}
        if d.name.startswith("MON_Alarm"):
            self.alarms[d.name] = AlarmView(
                _label(self.codec, d.name, "State", values.get("State")),
                values.get("J"),
                values.get("Threshold"),
                _label(self.codec, d.name, "Fault", values.get("Fault")),
                int(values.get("AlarmCount", 0)),
                now,
            )
        elif d.name == "MON_Status":
            self.status = {k: _label(self.codec, d.name, k, v) for k, v in values.items()}
            self.status_mono = now
        else:
            self.values.update({k: v for k, v in values.items() if k in SENSORS})

    # -- J1939 DM1, single frame or BAM ---------------------------------------------------

    def _j1939(self, msg: can.Message) -> bool:
        """Take a DM1 frame (or a BAM carrying one); False for anything else."""
        can_id = msg.arbitration_id
        pf, ps, sa = (can_id >> 16) & 0xFF, (can_id >> 8) & 0xFF, can_id & 0xFF
        pgn = (pf << 8) | (ps if pf >= 240 else 0)
        data = bytes(msg.data)
        if pgn == PGN_DM1:
            self._dm1(sa, data)
            return True
        if pgn == PGN_TP_CM and len(data) == 8 and data[0] == TP_CM_BAM:
            if int.from_bytes(data[5:8], "little") == PGN_DM1:
                self._bam[sa] = (int.from_bytes(data[1:3], "little"), data[3], bytearray())
            return True
        if pgn == PGN_TP_DT and sa in self._bam and len(data) == 8:
            size, count, buf = self._bam[sa]
            if data[0] != len(buf) // 7 + 1:  # a lost packet: wait for the next BAM
                del self._bam[sa]
                return True
            buf += data[1:]
            if data[0] == count:
                del self._bam[sa]
                self._dm1(sa, bytes(buf[:size]))
            return True
        return False

    def _dm1(self, sa: int, payload: bytes) -> None:
        if len(payload) < 2:  # no lamp bytes (a 0-byte frame, an empty BAM): not a DM1
            self.rejected["DM1"] = self.rejected.get("DM1", 0) + 1
            return
        lamps = [
            name
            for k, name in enumerate(("protect", "amber", "red", "mil"))
            if (payload[0] >> (2 * k)) & 0b11 == 0b01
        ]
        dtcs = []
        for k in range(2, len(payload) - 3, 4):
            b = payload[k : k + 4]
            spn = b[0] | (b[1] << 8) | ((b[2] >> 5) << 16)
            if spn == 0 and b[2] & 0x1F == 0:
                continue  # the no-DTC form
            dtcs.append(DtcView(spn, b[2] & 0x1F, b[3] & 0x7F))
        self.dm1[sa] = (lamps, dtcs)


def _label(codec: FrameCodec, message: str, signal: str, value: float | None) -> str:
    """A signal's value-table name (``fault``, ``spool_wear``...) or the number."""
    if value is None:
        return "?"
    sig = codec.message(message).dbc_message.get_signal_by_name(signal)
    if sig.choices and int(value) in sig.choices:
        return str(sig.choices[int(value)])
    return f"{value:g}" if isinstance(value, float) else str(value)
