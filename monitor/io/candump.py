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
from typing import TextIO

import can
from can.io.canutils import CanutilsLogReader

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
        log.warning("%s:%d: torn last line skipped (no newline at the end: the log was cut "
                    "off mid-line): %r", path, line_no, shown)  # fmt: skip
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


class _CheckedLines:
    """The log's lines, each checked against ``_LINE`` before python-can parses it.

    python-can's CanutilsLogReader gives no line numbers and is lenient: a foreign line
    such as ``0x1dc`` or a truncated last line ``(1606770`` raises a bare ValueError from
    tuple unpacking, and odd-length data such as ``123#ABC`` decodes silently to wrong
    bytes.  So we validate every line here (knowing its number) and let python-can build
    the messages from lines we know are well formed.
    """

    def __init__(self, fh: TextIO, path: Path) -> None:
        self._fh = fh
        self._path = path
        self.line_no = 0

    def __iter__(self) -> Iterator[str]:
        line_no = 0
        while True:
            # At most the limit (and a CRLF) at a time: one endless line must not be read whole.
            line = self._fh.readline(MAX_LINE_BYTES + 2)
            if not line:
                return
            line_no += 1
            self.line_no = line_no  # read by _messages when python-can itself fails
            if len(line) - line.endswith("\n") - line.rstrip("\n").endswith("\r") > MAX_LINE_BYTES:
                raise too_long_line(self._path, line_no)
            if "\x00" in line and line.endswith("\n"):
                raise nul_line(self._path, line_no)
            text = line.strip()
            problem = line_problem(text) if text else None
            if problem:
                skip_odd_line(text, self._path, line_no, not line.endswith("\n"), problem)
                continue
            yield line

    def close(self) -> None:
        self._fh.close()


def read_candump(path: str | Path) -> Iterator[can.Message]:
    """Messages of a candump log, in file order, read with python-can's CanutilsLogReader.

    The file is opened at once (a missing file fails here); a malformed line raises
    ``InputFileError`` naming file and line when iteration reaches it.  Blank lines, comment
    lines and a torn last line are skipped (``skip_odd_line``).
    """
    p = Path(path)
    try:
        # errors="replace": a binary or non-ASCII line becomes a line error, not a crash.
        # newline="\n": lines end at LF only (a CR LF's CR is stripped with the line), as in
        # the bulk reader; a lone CR is inside a line, which is then malformed.
        fh = p.open("r", encoding="utf-8", errors="replace", newline="\n")
    except OSError as exc:
        raise InputFileError(f"{p}: cannot read: {exc.strerror or exc}") from None
    return _messages(_CheckedLines(fh, p), p)


def _messages(lines: _CheckedLines, path: Path) -> Iterator[can.Message]:
    reader = CanutilsLogReader(lines)
    try:
        yield from reader
    except InputFileError:
        raise
    except (ValueError, IndexError) as exc:  # a line our check let through but can cannot use
        raise InputFileError(f"{path}:{lines.line_no}: unreadable candump line: {exc}") from None
    finally:
        lines.close()
