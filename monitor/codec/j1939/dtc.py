"""J1939-73 diagnostic message layout: DTCs, lamp bytes and the DM1/DM2 payload.

A DM1 (PGN 65226) or DM2 (PGN 65227) payload is two lamp bytes followed by one 4-byte
DTC per trouble code, in the current SPN layout (conversion method bit CM = 0):

    byte 0  lamp status, 2 bits each: MIL bits 8-7, red stop 6-5, amber warning 4-3,
            protect 2-1 (00 off, 01 on)
    byte 1  flash, same positions (00 slow 1 Hz, 01 fast 2 Hz, 11 do not flash)
    DTC     SPN bits 0-7 | SPN bits 8-15 | SPN bits 16-18 in the top 3 bits, FMI in the
            low 5 | CM bit 8, occurrence count in bits 7-1 (127: not available)

With no active DTC the payload is the J1939-73 "no DTC" form: lamps off, SPN 0, FMI 0,
OC 0, padded to 8 bytes with 0xFF.
"""

from __future__ import annotations

from dataclasses import dataclass

from monitor.errors import ConfigError

PGN_DM1 = 65226  # 0xFECA active diagnostic trouble codes
PGN_DM2 = 65227  # 0xFECB previously active diagnostic trouble codes

SPN_MAX = (1 << 19) - 1  # 524287: the SPN field is 19 bits
FMI_MAX = 31  # 5 bits
OC_MAX = 126  # 127 means "not available" (J1939-73), so a count saturates at 126

# SAE J1939-71 assigns SPNs 520192-524287 (0x7F000-0x7FFFF, the last 4096 of the 19-bit
# space) to proprietary use: a manufacturer's own parameters, never standard ones.  Our
# defaults live there; a machine builder may map them to its own or to standard SPNs.
PROPRIETARY_SPN_FIRST = 520192
DEFAULT_FAULT_SPN = {
    "piston_wear": PROPRIETARY_SPN_FIRST,
    "spool_stroke": PROPRIETARY_SPN_FIRST + 1,
    "spool_wear": PROPRIETARY_SPN_FIRST + 2,
    "unknown": PROPRIETARY_SPN_FIRST + 3,  # a hydraulic fault isolation could not name
    "pump_wear": PROPRIETARY_SPN_FIRST + 4,  # the shared pump's rule (a whole machine's)
}
# FMI 7: mechanical system not responding or out of adjustment; 11: root cause not known.
DEFAULT_FAULT_FMI = {
    "piston_wear": 7,
    "spool_stroke": 7,
    "spool_wear": 7,
    "unknown": 11,
    "pump_wear": 7,
}
DEFAULT_SENSOR_SPN = {
    name: PROPRIETARY_SPN_FIRST + 16 + i
    for i, name in enumerate(
        ("SpoolCmd", "PumpDispCmd", "EngineSpeed", "OilTemp", "PP", "PA", "PB", "QP", "RodPos")
    )
} | {"unknown": PROPRIETARY_SPN_FIRST + 31}  # a sensor fault no stale signal explains
DEFAULT_SENSOR_FMI = 9  # abnormal update rate: the signal's frames stopped or went stale
# A sensor named by a plausibility check keeps its signal's SPN with
# the FMI of what was found (J1939-73 FMI table): 2 data erratic or incorrect (outside the
# sensor's range), 10 abnormal rate of change (frozen, or stuck while the loop moves),
# 13 out of calibration (an offset against the pump/port relation or at rest).
DEFAULT_CHECK_FMI = {
    "signal_range": 2,
    "frozen": 10,
    "stuck": 10,
    "pump_below_port": 13,
    "rest_offset": 13,
}

LAMPS = ("protect", "amber", "red", "mil")  # bit pairs 1-2, 3-4, 5-6, 7-8 of bytes 0 and 1
FLASH = {"slow": 0b00, "fast": 0b01}
NO_FLASH = 0b11


@dataclass(frozen=True, order=True)
class Dtc:
    spn: int
    fmi: int
    oc: int = 0  # occurrence count

    def pack(self) -> bytes:
        """The 4 DTC bytes (conversion method 1, CM bit 0)."""
        oc = min(self.oc, 127)
        return bytes(
            (
                self.spn & 0xFF,
                (self.spn >> 8) & 0xFF,
                ((self.spn >> 16) & 0x07) << 5 | (self.fmi & 0x1F),
                oc & 0x7F,  # CM (bit 8) 0
            )
        )


@dataclass(frozen=True)
class Lamp:
    """One lamp of the DM1 lamp bytes, lit steadily or flashing; ``name`` None: no lamp."""

    name: str | None
    flash: str | None = None

    @classmethod
    def parse(cls, text: str, where: str) -> Lamp:
        """``none``, a lamp name, or ``name:slow`` / ``name:fast``."""
        name, _, flash = text.partition(":")
        if name == "none" and not flash:
            return cls(None)
        if name not in LAMPS or (flash and flash not in FLASH):
            raise ConfigError(
                f"{where} must be none or one of {', '.join(LAMPS)}, optionally with "
                f":slow or :fast, got {text!r}"
            )
        return cls(name, flash or None)


def lamp_bytes(lamps: set[Lamp] | frozenset[Lamp]) -> bytes:
    """Bytes 0-1: every lamp off and not flashing, except those lit by an active DTC.

    When two DTCs light the same lamp with different flash codes, fast wins over slow over
    steady (the most urgent indication)."""
    status, flash = 0, 0xFF
    rank = {None: 0, "slow": 1, "fast": 2}
    best: dict[str, str | None] = {}
    for lamp in lamps:
        if lamp.name is not None and (
            lamp.name not in best or rank[lamp.flash] > rank[best[lamp.name]]
        ):
            best[lamp.name] = lamp.flash
    for name, fl in best.items():
        shift = 2 * LAMPS.index(name)
        status |= 0b01 << shift
        code = NO_FLASH if fl is None else FLASH[fl]
        flash = (flash & ~(0b11 << shift)) | (code << shift)
    return bytes((status, flash))


def dm_payload(lamps: bytes, dtcs: list[Dtc] | tuple[Dtc, ...]) -> bytes:
    """A DM1/DM2 payload: lamp bytes and DTCs, or the no-DTC form padded to 8 bytes."""
    if not dtcs:
        return lamps + Dtc(0, 0, 0).pack() + b"\xff\xff"
    return lamps + b"".join(d.pack() for d in dtcs)


def check_number_map(
    raw: dict[str, object], known: tuple[str, ...], top: int, where: str
) -> dict[str, int]:
    """A name -> whole number map with known names and values 0..``top``."""
    out: dict[str, int] = {}
    for key, value in raw.items():
        if key not in known:
            raise ConfigError(f"unknown name {where}.{key}; known: {', '.join(known)}")
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= top:
            text = repr(value) if len(repr(value)) <= 60 else repr(value)[:57] + "..."
            raise ConfigError(f"{where}.{key} must be a whole number 0..{top}, got {text}")
        out[key] = value
    return out
