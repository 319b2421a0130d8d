"""An independent J1939 reading of our frames: python-can-j1939 (``can-j1939``) reassembles
single frames and BAMs into parameter groups and parses DTCs and lamps; cantools splits
the IDs and decodes single-frame DM1/DM2 with dbc/j1939_dm.dbc."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import can
import cantools
import j1939
from cantools.j1939 import frame_id_unpack, pgn_from_frame_id

from monitor.resources import resource_path

DM1_ID = 0x18FECAA0
TP_CM_ID = 0x1CECFFA0
TP_DT_ID = 0x1CEBFFA0
_LAMP_KEYS = {"pl": "protect", "awl": "amber", "rsl": "red", "mil": "mil"}
_STATUS = {
    j1939.DtcLamp.OFF: "off",
    j1939.DtcLamp.ON: "on",
    j1939.DtcLamp.ON_SLOW_FLASH: "slow",
    j1939.DtcLamp.ON_FAST_FLASH: "fast",
    j1939.DtcLamp.NA: "n/a",
}


def reassemble(frames: Iterable[can.Message]) -> list[dict[str, Any]]:
    """Parameter groups as can-j1939's J1939-21 receiver delivers them (BAMs joined)."""
    ecu = j1939.ElectronicControlUnit()
    got: list[dict[str, Any]] = []
    ecu.subscribe(
        lambda prio, pgn, sa, ts, data: got.append(
            {"priority": prio, "pgn": pgn, "sa": sa, "t": ts, "data": bytes(data)}
        )
    )
    try:
        for m in frames:
            ecu.notify(m.arbitration_id, bytearray(m.data), m.timestamp)
    finally:
        ecu.stop()
    return got


def decode_dm(data: bytes) -> tuple[dict[str, str], list[tuple[int, int, int]]]:
    """Lamps (name -> off/on/slow/fast) and (SPN, FMI, OC) of each DTC, by can-j1939."""
    lamp = j1939.DtcLamp()
    lamps = {}
    for i, key in enumerate(("pl", "awl", "rsl", "mil")):
        status = lamp.get_status((data[0] >> 2 * i) & 3, (data[1] >> 2 * i) & 3)
        lamps[_LAMP_KEYS[key]] = _STATUS[status]
    dtcs = []
    for k in range((len(data) - 2) // 4):
        d = j1939.DTC(dtc=int.from_bytes(data[2 + 4 * k : 6 + 4 * k], "little"))
        assert d.cm == 0
        dtcs.append((d.spn, d.fmi, d.oc))
    return lamps, dtcs


def pgn_of(frame_id: int) -> int:
    return pgn_from_frame_id(frame_id)


def source_of(frame_id: int) -> int:
    return frame_id_unpack(frame_id).source_address


def dm_dbc() -> cantools.database.Database:
    return cantools.database.load_file(resource_path("dbc", "j1939_dm.dbc"))
