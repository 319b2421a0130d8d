"""candump logs (``candump -L`` format): reading frames, formatting lines.

Writing a Recording as frames needs the DBC: monitor/codec/logwrite.py.

A line is ``(1700000000.000000) can0 0CFF1021#3930409C00000032``: timestamp in seconds,
interface, id (3 hex digits standard, 8 extended), ``#``, data in hex.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Iterator
from pathlib import Path

import can

from monitor.errors import InputFileError

log = logging.getLogger("monitor")

#: Log time of the recording's t = 0 when writing (2023-11-14 22:13:20 UTC), a fixed
#: epoch so that encoding the same CSV twice gives the same log.
DEFAULT_START_TIME_S = 1_700_000_000.0

# One line of a candump -L log, strictly: classic data (0-8 bytes), remote (R, optional
# DLC), CAN FD (##flags + up to 64 bytes), and python-can's optional " R"/" T" direction.
_LINE = re.compile(
    r"\(\d+\.\d+\)[ \t]+\S+[ \t]+(?:[0-9A-Fa-f]{3}|[0-9A-Fa-f]{8})#"
    r"(?:[Rr]\d{0,2}|#[0-9A-Fa-f](?:[0-9A-Fa-f]{2}){0,64}|(?:[0-9A-Fa-f]{2}){0,8})"
    r"(?:[ \t]+[RTrt])?"
)

#: Longest line a log may have.  A CAN FD line with 64 data bytes is some 170 characters, so
#: a longer one is a binary or corrupt file (a 2 GB sparse file is one line of NULs); refusing
#: it as soon as it passes the limit keeps the reader's memory bounded.
MAX_LINE_BYTES = 1000
#: Timestamps a log may carry: seconds from 0 up to 1e11 (the year 5138), at most
#: ``MAX_TIMESTAMP_DIGITS`` digits before the point.  A larger one is a corrupt line; taken
#: as time it would make the sample clock span millennia.
MAX_TIMESTAMP_S = 1e11
MAX_TIMESTAMP_DIGITS = 20


def format_line(
    timestamp_s: float, channel: str, frame_id: int, extended: bool, data: bytes
) -> str:
    """One ``candump -L`` line (with its newline)."""
    ident = f"{frame_id:08X}" if extended else f"{frame_id:03X}"
    return f"({timestamp_s:.6f}) {channel} {ident}#{data.hex().upper()}\n"


def line_problem(text: str) -> str | None:
    """Why a stripped, non-blank line is not a frame of a candump -L log, or None."""
    if "\x00" in text:
        return "NUL bytes, not a text log"
    if not _LINE.fullmatch(text):
        return "not a candump -L line"
    stamp = text[1 : text.index(")")]  # _LINE: "(" digits "." digits ")"
    whole = stamp.index(".")
    if whole > MAX_TIMESTAMP_DIGITS:
        return f"timestamp with {whole} digits before the point (at most {MAX_TIMESTAMP_DIGITS})"
    if float(stamp) > MAX_TIMESTAMP_S:
        shown = stamp if len(stamp) <= 30 else stamp[:27] + "..."
        return f"timestamp {shown} s out of range (0 to {MAX_TIMESTAMP_S:.0e} s)".replace("e+", "e")
    return None


def skip_odd_line(
    text: str, path: Path, line_no: int, unterminated: bool, problem: str | None = None
) -> None:
    """A line that is not a frame: return to skip it, raise ``InputFileError`` otherwise.

    Skipped: comment lines (``#`` first, as some loggers write a header) and a torn last
    line: one without its newline, which is what a power cut leaves at the end of a log being
    written (warned once, naming file and line).  Any other malformed line is an error
    naming file and line; ``problem`` (from ``line_problem``) says what is wrong with it.
    """
    shown = text if len(text) <= 60 else text[:57] + "..."
    if text.startswith("#"):
        return
    if unterminated:
        log.warning(
            "%s:%d: torn last line skipped (no newline at the end: the log was cut "
            "off mid-line): %r",
            path,
            line_no,
            shown,
        )
        return
    problem = problem or "not a candump -L line"
    raise InputFileError(
        f"{path}:{line_no}: {problem}: {shown!r} (expected '(SECONDS) IFACE ID#HEXDATA')"
    )


def nul_line(path: Path, line_no: int) -> InputFileError:
    """The error for a whole line (newline and all) with a NUL byte: a binary file.  NULs in
    an unterminated last line are a torn line's (a power cut), skipped with it."""
    return InputFileError(f"{path}:{line_no}: NUL bytes, not a text log (a candump -L log is text)")


def too_long_line(path: Path, line_no: int) -> InputFileError:
    """The error for a line longer than ``MAX_LINE_BYTES`` (a binary or corrupt file)."""
    return InputFileError(
        f"{path}:{line_no}: line longer than {MAX_LINE_BYTES} bytes, not a candump -L log"
        " (a binary or corrupt file?)"
    )


def read_candump(path: str | Path) -> Iterator[can.Message]:
    """Messages of a candump log, in file order, from the one parser
    (``monitor.io.candump_bulk.read_candump_frames``).

    The whole file is read and checked first: a missing file or a malformed line raises
    ``InputFileError`` naming file and line before the first message.  Blank lines, comment
    lines and a torn last line are skipped (``skip_odd_line``).
    """
    from monitor.io.candump_bulk import read_candump_frames  # it builds on this module

    return read_candump_frames(path).messages()
