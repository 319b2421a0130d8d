"""candump logs (``candump -L`` format): writing a Recording as frames, reading frames back.

A line is ``(1700000000.000000) can0 0CFF1021#3930409C00000032``: timestamp in seconds,
interface, id (3 hex digits standard, 8 extended), ``#``, data in hex.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from pathlib import Path
from typing import TextIO

import can
import numpy as np
from can.io.canutils import CanutilsLogReader

from monitor.codec.frames import FrameCodec
from monitor.errors import InputFileError
from monitor.io.recording import Recording

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


def format_line(
    timestamp_s: float, channel: str, frame_id: int, extended: bool, data: bytes
) -> str:
    """One ``candump -L`` line (with its newline)."""
    ident = f"{frame_id:08X}" if extended else f"{frame_id:03X}"
    return f"({timestamp_s:.6f}) {channel} {ident}#{data.hex().upper()}\n"


def _due_rows(t: np.ndarray, ok: np.ndarray, cycle_s: float, period_s: float) -> list[int]:
    """Rows at which a message with cycle ``cycle_s`` is sent.

    A frame goes out at a row whose values are all present (``ok``) once at least one
    cycle (less half a sample period, for row jitter) has passed since the last one.
    For 10 ms messages on 10 ms rows that is every row with data; for the 1 s oil
    temperature it is one row a second, and a CSV that fills OilTemp only once a second
    still gets its frames.
    """
    rows: list[int] = []
    last = -math.inf
    min_gap = cycle_s - 0.5 * period_s
    tt = t.tolist()
    for i in np.flatnonzero(ok).tolist():
        if tt[i] - last >= min_gap:
            rows.append(i)
            last = tt[i]
    return rows


def write_candump(
    path: str | Path,
    rec: Recording,
    codec: FrameCodec | None = None,
    start_time_s: float = DEFAULT_START_TIME_S,
    channel: str = "can0",
    period_s: float = 0.01,
) -> dict[str, int]:
    """Write ``rec`` as a candump log; return the number of frames written per message.

    Every DBC message whose physical signals are all columns of ``rec`` is sent at its
    GenMsgCycleTime (so HYD_RodPos only when the recording has RodPos, HYD_OilTemp once a
    second).  A row with NaN in any signal of a message skips that frame: missing data
    stays missing on the bus.  Frame time is ``start_time_s + t``; counters and CRCs
    come from ``codec`` (default: the shipped DBC), values are clipped to the DBC ranges.
    """
    # We format lines ourselves instead of using python-can's CanutilsLogWriter: it
    # appends a direction flag (" R"/" T") that plain `candump -L` does not write and that
    # strict parsers of other tools reject, and it needs a can.Message per frame.
    # python-can's CanutilsLogReader reads our lines (tested).
    codec = codec or FrameCodec.from_dbc()
    t = rec.t
    plans: list[tuple[str, list[str], list[int]]] = []
    for info in codec.messages.values():
        names = list(info.signal_names)
        if not names or info.cycle_time_s is None or not all(rec.has(n) for n in names):
            continue
        ok = np.ones(len(t), dtype=bool)
        for n in names:
            ok &= np.isfinite(rec[n])
        plans.append((info.name, names, _due_rows(t, ok, info.cycle_time_s, period_s)))

    # Merge to time order; within a row, messages keep the DBC order.
    events = sorted((i, k) for k, (_, _, rows) in enumerate(plans) for i in rows)
    lists = {n: rec[n].tolist() for _, names, _ in plans for n in names}
    counts = {name: 0 for name, _, _ in plans}
    stamps = (start_time_s + t).tolist()
    p = Path(path)
    try:
        with p.open("w", encoding="ascii", newline="\n") as fh:
            buf: list[str] = []
            for i, k in events:
                name, names, _ = plans[k]
                info = codec.messages[name]
                data = codec.encode(name, {n: lists[n][i] for n in names})
                buf.append(format_line(stamps[i], channel, info.frame_id, info.is_extended_id,
                                       data))
                counts[name] += 1
                if len(buf) >= 4096:
                    fh.writelines(buf)
                    buf.clear()
            fh.writelines(buf)
    except OSError as exc:
        raise InputFileError(f"{p}: cannot write: {exc.strerror or exc}") from None
    return counts


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
        for line_no, line in enumerate(self._fh, start=1):
            self.line_no = line_no  # read by _messages when python-can itself fails
            text = line.strip()
            if text and not _LINE.fullmatch(text):
                shown = text if len(text) <= 60 else text[:57] + "..."
                raise InputFileError(
                    f"{self._path}:{self.line_no}: not a candump -L line: {shown!r}"
                    " (expected '(SECONDS) IFACE ID#HEXDATA')"
                )
            yield line

    def close(self) -> None:
        self._fh.close()


def read_candump(path: str | Path) -> Iterator[can.Message]:
    """Messages of a candump log, in file order, read with python-can's CanutilsLogReader.

    The file is opened at once (a missing file fails here); a malformed line raises
    ``InputFileError`` naming file and line when iteration reaches it.  Blank lines are
    skipped.
    """
    p = Path(path)
    try:
        # errors="replace": a binary or non-ASCII line becomes a line error, not a crash.
        fh = p.open("r", encoding="utf-8", errors="replace")
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
