"""Plain-Python references for reading frames, written apart from the product's kernels:
the sample clock's rule (recursive, as its prose says), python-can's line-by-line candump
reader behind a line check, and the frame-by-frame recording (reader -> FrameCodec ->
Sampler, as the daemon takes frames off the bus).  Slow and obvious on purpose."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path
from typing import TextIO

import can
import numpy as np
from can.io.canutils import CanutilsLogReader

from monitor.codec.frames import FrameCodec
from monitor.errors import InputFileError
from monitor.io.candump import (
    MAX_LINE_BYTES,
    line_problem,
    nul_line,
    skip_odd_line,
    too_long_line,
)
from monitor.io.recording import Recording
from monitor.sampling.sampler import (
    MIN_ROW_LIMIT,
    Sampler,
    hydraulic_messages,
    no_hydraulic_data,
    row_limit,
    runs_backwards,
    too_many_rows,
)
from monitor.signals import ROD_POS


def sample_clock(ts, period, max_gap, resync, eps, outage):
    """The sample clock's time rule written as the prose of ``monitor.sampling.clock`` says,
    recursively: (sampler time per frame or NaN when skipped, frames in application order,
    whether each applied frame ended an outage, [backwards, skipped, resyncs, gaps])."""
    ts = [float(t) for t in ts]
    st_out = [math.nan] * len(ts)
    order, resumes, counts = [], [], [0, 0, 0, 0]
    clock = {"offset": -ts[0] if ts else 0.0, "newest": -math.inf}
    held: list[int] = []

    def feed(f):
        st = ts[f] + clock["offset"]
        newest = clock["newest"]
        if st < newest - eps:
            counts[0] += 1
            if newest - st <= period:
                st = newest
            else:
                held.append(f)
                if len(held) == resync:
                    clock["offset"] = newest + period - ts[held[0]]
                    counts[2] += 1
                    replay = held[:]
                    held.clear()
                    for g in replay:
                        feed(g)
                return
        elif held:
            counts[1] += len(held)
            held.clear()
        if newest > -math.inf and st - newest > max_gap:
            clock["offset"] -= st - newest - max_gap
            st = newest + max_gap
            counts[3] += 1
        st_out[f] = st
        order.append(f)
        resumes.append(st - newest >= outage)
        clock["newest"] = st

    for f in range(len(ts)):
        feed(f)
    return np.array(st_out), np.array(order, dtype=np.int64), np.array(resumes), counts


def recording_from_candump(path, codec=None):
    """The frame-by-frame reference of ``monitor.sampling.bulk.recording_from_candump_bulk``
    (what ``monitor detect`` reads a log with): python-can's reader -> ``FrameCodec`` ->
    ``Sampler``, one frame at a time, as the daemon takes frames off the bus.

    ``meta["counts"]`` holds the log's frame counts: frames read, decoded, ignored
    (unknown id), rejected by reason, counter jumps, and the sampler's time counts.
    Raises ``InputFileError`` for a malformed line or a log needing more than
    ``row_limit(frames)`` rows, and ``NoHydraulicDataError`` (exit 3) when no valid
    hydraulic frame of the DBC is in the log.
    """
    codec = codec or FrameCodec.from_dbc()
    codec.reset_counters()
    sampler = Sampler.for_codec(codec)
    hydraulic = hydraulic_messages(codec)
    # The frames are known only at the end; the file's lines bound them, so rows beyond
    # row_limit(lines) are refused anyway and need not be kept (lines counted when needed).
    most: int | None = None
    chunks: list[np.ndarray] = []
    decode, feed = codec.decode_message, sampler.feed
    first, last = math.inf, -math.inf
    fed = 0
    for msg in read_candump_lines(path):
        d = decode(msg)
        if d.rejection is None and d.name in hydraulic:
            feed(msg.timestamp, d.name, d.values)  # type: ignore[arg-type]
            fed += 1
            first, last = min(first, msg.timestamp), max(last, msg.timestamp)
            if sampler.pending >= 8192:  # lists of floats cost more memory than arrays
                rows = sampler.take()
                if most is None and sampler.rows > MIN_ROW_LIMIT:
                    most = row_limit(_count_lines(path))
                if most is None or sampler.rows <= most:
                    chunks.append(rows)
    counts = {**codec.counts.as_dict(), **sampler.counts.as_dict()}
    if not sampler.started:
        raise no_hydraulic_data(path, counts)
    chunks.append(sampler.flush())
    frames = counts["frames"]
    if sampler.rows > row_limit(frames):
        raise too_many_rows(path, sampler.rows, frames, last - first, counts["time_resyncs"])
    if err := runs_backwards(path, fed, counts):
        raise err
    rows = np.concatenate(chunks)
    columns = {
        name: rows[:, 1 + i]
        for i, name in enumerate(sampler.columns)
        if name != ROD_POS.name or ROD_POS.name in sampler.seen
    }
    meta: dict[str, object] = {
        "format": "candump",
        "start_time_s": sampler.start_time_s,
        "counts": counts,
    }
    return Recording(t=rows[:, 0], columns=columns, source=str(path), meta=meta)


def _count_lines(path: str | Path) -> int:
    """Lines of a file (an unterminated last one counted), read in chunks; 0 if unreadable
    (``read_candump_lines`` then says why)."""
    n, last = 0, b"\n"
    try:
        with open(path, "rb") as fh:
            while chunk := fh.read(1 << 20):
                n += chunk.count(b"\n")
                last = chunk[-1:]
    except OSError:
        return 0
    return n + (last != b"\n")


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


def read_candump_lines(path: str | Path) -> Iterator[can.Message]:
    """Messages of a candump log, in file order, read line by line with python-can's
    CanutilsLogReader behind the line check: the reference of the bulk parser.

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


def counter_believed(counters: list[int], resync: int = 3) -> list[bool]:
    """Which frames of one message the alive-counter rule believes, by its prose: the first
    frame, then a frame 1 or 2 after the last believed one (one frame lost), or one that
    repeats the last believed one or is one behind it while 1 or 2 after the believed one
    before that (it takes the last one's place); any other is not believed, until
    ``resync`` frames in a row have counters each 1 after the one before, the last of them
    believed again (with no believed one before it).  Plain lists of the frames seen."""
    out: list[bool] = []
    believed: list[int] = []  # believed counters since the first or the last resync
    since: list[int] = []  # counters not believed since the last believed frame
    for c in counters:
        after = (c - believed[-1]) % 16 if believed else None
        if after is None or after in (1, 2):
            believed.append(c)
            ok = True
        elif after in (0, 15) and len(believed) > 1 and (c - believed[-2]) % 16 in (1, 2):
            believed[-1] = c
            ok = True
        else:
            since.append(c)
            tail = 1
            while tail < len(since) and (since[-tail] - since[-tail - 1]) % 16 == 1:
                tail += 1
            ok = tail >= resync
            if ok:
                believed = [c]
        if ok:
            since = []
        out.append(ok)
    return out
