"""CAN codec: DBC loading, CRC-8/SAE-J1850, frame encode/decode with counter and CRC checks."""

from monitor.codec.crc import crc8_sae_j1850
from monitor.codec.dbc import default_dbc_path, load_dbc
from monitor.codec.frames import DecodeCounts, Decoded, FrameCodec, Rejection
from monitor.codec.layout import MessageInfo, SignalInfo

__all__ = [
    "DecodeCounts",
    "Decoded",
    "FrameCodec",
    "MessageInfo",
    "Rejection",
    "SignalInfo",
    "crc8_sae_j1850",
    "default_dbc_path",
    "load_dbc",
]
