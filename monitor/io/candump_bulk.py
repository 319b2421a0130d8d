"""candump -L logs read in bulk: the whole file into numpy arrays of frames, no per-line Python.
The one candump parser: ``monitor detect`` takes the arrays, ``read_candump`` (replay onto a
bus) the messages made of them.

python-can's CanutilsLogReader builds one ``can.Message`` per line, about 10 us each, and is
lenient with malformed lines.  Here the file is one byte array: a numba pass
finds each line's bounds, its two spaces and its ``#``, a second one turns the fields of
the plain lines into timestamp, id and data bytes (hex by table lookup; both passes in
``monitor.io.candump_scan``).  Timestamps are
N / 10^k with exact N and 10^k, so IEEE division gives the correctly rounded value that
python-can's ``float()`` gives, bit for bit (numpy's string-to-float for the rare longer
ones).

Only the plain form ``(SECONDS) IFACE ID#HEXDATA`` (classic frame, 0-8 bytes, single spaces,
optional ``\\r``) takes the fast path.  Any other line (remote, CAN FD, direction flag,
tabs, stray text) goes through the line check and python-can's reader, one line at a time,
so it means what it means to python-can, and a malformed line raises an ``InputFileError``
naming file and line (``line_problem``).

The file is read in chunks, each checked before the next: a line longer than
``MAX_LINE_BYTES`` or a NUL byte in a whole line stops the read there (a binary file, a
2 GB sparse file), so refusing it costs one chunk of memory, not the file.  (So the line
named may come after a malformed line that a line-by-line reader would name first.)  The lines
are parsed a block at a time, so the memory beyond the frames kept is one block's.
"""

from __future__ import annotations

import io
import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import can
import numpy as np
from can.io.canutils import CAN_ERR_BUSERROR, CAN_ERR_FLAG, CanutilsLogReader

from monitor.errors import InputFileError
from monitor.io.candump import (
    MAX_LINE_BYTES,
    line_problem,
    nul_line,
    skip_odd_line,
    too_long_line,
)
from monitor.io.candump_scan import parse_fast, scan_lines


@dataclass
class Frames:
    """Frames of a log in file order (the fields of python-can's Message that decoding uses).

    ``data`` is (n, width) zero-padded, ``length`` the number of data bytes (0 for remote);
    ``fd`` marks CAN FD frames, ``brs``/``esi`` their bit-rate-switch and error-state flags.
    """

    timestamp: np.ndarray  # float64, s
    can_id: np.ndarray  # int64 arbitration id (29 or 11 bit)
    extended: np.ndarray  # bool
    remote: np.ndarray  # bool
    error: np.ndarray  # bool
    length: np.ndarray  # int64
    data: np.ndarray  # uint8 (n, width)
    fd: np.ndarray  # bool
    brs: np.ndarray  # bool
    esi: np.ndarray  # bool

    def __len__(self) -> int:
        return int(self.timestamp.shape[0])

    def messages(self) -> Iterator[can.Message]:
        """The frames as python-can messages, in file order (as python-can's reader makes
        them of the lines, without the interface name and direction)."""
        cols = zip(
            self.timestamp.tolist(),
            self.can_id.tolist(),
            self.extended.tolist(),
            self.remote.tolist(),
            self.error.tolist(),
            self.length.tolist(),
            self.fd.tolist(),
            self.brs.tolist(),
            self.esi.tolist(),
            strict=True,
        )
        for i, (ts, can_id, ext, remote, error, n, fd, brs, esi) in enumerate(cols):
            if error:
                yield can.Message(timestamp=ts, is_error_frame=True)
                continue
            yield can.Message(
                timestamp=ts,
                arbitration_id=can_id,
                is_extended_id=ext,
                is_remote_frame=remote,
                dlc=None if remote else n,
                data=None if remote else self.data[i, :n].tobytes(),
                is_fd=fd,
                bitrate_switch=brs,
                error_state_indicator=esi,
            )


def read_candump_frames(path: str | Path) -> Frames:
    """All frames of a candump -L log; ``InputFileError`` for a missing file or a bad line.

    The file is parsed block by block (``_BLOCK`` bytes of whole lines), so the memory
    spent beyond the frames kept is one block's, whatever the number of lines (8 MB of blank
    lines took 765 MB read whole)."""
    p = Path(path)
    parts: list[Frames] = []
    try:
        for raw, first, last in _read_blocks(p):
            parts.append(_block_frames(raw, first, last, p))
    except OSError as exc:
        raise InputFileError(f"{p}: cannot read: {exc.strerror or exc}") from None
    return _concat(parts)


def _block_frames(raw: bytearray, first: int, last: bool, p: Path) -> Frames:
    """The frames of one block of whole lines (the file's last block if ``last``); ``first``
    is the number of lines before it, for messages."""
    buf = np.frombuffer(raw, dtype=np.uint8)
    starts, ends, sp1, sp2, hs, ok = scan_lines(buf)
    fast = np.flatnonzero(ok)
    pos = {"sp1": sp1[fast], "sp2": sp2[fast], "hash": hs[fast]}
    fields, good = parse_fast(buf, starts[fast], ends[fast], pos)
    is_fast = np.zeros(starts.size, dtype=bool)
    is_fast[fast[good]] = True
    others = np.flatnonzero(~is_fast & (ends > starts))  # an empty line is skipped here
    slow = _parse_slow(raw, starts, ends, others, p, first, last)
    return _merge({k: v[good] for k, v in fields.items()}, fast[good], slow)


def _concat(parts: list[Frames]) -> Frames:
    if len(parts) == 1:
        return parts[0]
    width = max(f.data.shape[1] for f in parts)
    data = np.concatenate([np.pad(f.data, ((0, 0), (0, width - f.data.shape[1]))) for f in parts])
    cols = {
        k: np.concatenate([getattr(f, k) for f in parts])
        for k in (
            "timestamp",
            "can_id",
            "extended",
            "remote",
            "error",
            "length",
            "fd",
            "brs",
            "esi",
        )
    }
    return Frames(data=data, **cols)


_CHUNK = 1 << 18
#: Bytes of whole lines parsed at a time: the per-line work arrays (some 50 bytes a line)
#: are one block's.
_BLOCK = 1 << 18


def _read_blocks(p: Path) -> Iterator[tuple[bytearray, int, bool]]:
    """(bytes of whole lines, lines before them, whether they end the file), read chunk by
    chunk and refused at the first line longer than ``MAX_LINE_BYTES`` or the first whole
    line with a NUL byte (``InputFileError`` naming it).  NULs in an unterminated last line
    are left to the torn-line rule."""
    data = bytearray()
    given = 0  # lines in the blocks handed out
    lines_before = 0  # newlines before the current chunk
    line_len = 0  # bytes of the current line before the current chunk
    pending_nul = 0  # line number of a NUL not yet followed by a newline
    with p.open("rb") as fh:
        while chunk := fh.read(_CHUNK):
            arr = np.frombuffer(chunk, dtype=np.uint8)
            nl = np.flatnonzero(arr == 10)
            lengths = np.diff(nl, prepend=-1 - line_len) - 1  # of the lines ending here
            before = np.where(nl > 0, arr[nl - 1], data[-1] if data else 10)
            lengths -= before == 13  # a CR before the LF is not part of the line
            tail = arr.size - 1 - nl[-1] if nl.size else line_len + arr.size
            # The first offending line, as the line-by-line reader meets it (length first).
            long = np.flatnonzero(lengths > MAX_LINE_BYTES)
            long_no = (
                lines_before + int(long[0]) + 1
                if long.size
                else lines_before + nl.size + 1
                if tail > MAX_LINE_BYTES + 1
                else math.inf
            )
            nuls = np.flatnonzero(arr == 0)
            k = int(np.searchsorted(nl, nuls[0])) if nuls.size else -1  # its line in the chunk
            nul_no = (
                pending_nul
                if pending_nul and nl.size
                else lines_before + k + 1
                if 0 <= k < nl.size
                else math.inf
            )
            if long_no <= nul_no and long_no < math.inf:
                raise too_long_line(p, int(long_no))
            if nul_no < math.inf:
                raise nul_line(p, int(nul_no))
            if k == nl.size:  # in the unterminated tail so far
                pending_nul = pending_nul or lines_before + k + 1
            lines_before += nl.size
            line_len = int(tail)
            data += chunk
            if len(data) >= _BLOCK and nl.size:
                cut = len(data) - int(tail)  # after the last newline
                yield data[:cut], given, False
                given = lines_before
                del data[:cut]
    if line_len > MAX_LINE_BYTES and (not data or data[-1] != 13):  # the unterminated last line
        raise too_long_line(p, lines_before + 1)
    yield data, given, True


def _parse_slow(
    raw: bytes | bytearray, starts, ends, lines: np.ndarray, path: Path, first: int, last: bool
) -> list[tuple[int, can.Message]]:
    """(line index, Message) for the other lines, through the line check and python-can;
    ``first`` lines come before ``raw`` in the file, ``last``: ``raw`` ends the file."""
    out: list[tuple[int, can.Message]] = []
    for i in lines.tolist():
        text = raw[starts[i] : ends[i]].decode("utf-8", errors="replace").strip()
        if not text:
            continue
        problem = line_problem(text)
        if problem:
            unterminated = last and i == len(starts) - 1 and not raw.endswith(b"\n")
            skip_odd_line(text, path, first + i + 1, unterminated, problem)
            continue
        try:
            msgs = list(CanutilsLogReader(io.StringIO(text)))
        except (ValueError, IndexError) as exc:
            where = f"{path}:{first + i + 1}"
            raise InputFileError(f"{where}: unreadable candump line: {exc}") from None
        out.extend((i, m) for m in msgs)
    return out


def _merge(
    fast: dict[str, np.ndarray], fast_lines: np.ndarray, slow: list[tuple[int, can.Message]]
) -> Frames:
    nf, ns = fast_lines.size, len(slow)
    if ns == 0:  # every line plain: already in file order
        error = ((fast["can_id"] & CAN_ERR_FLAG) != 0) & ((fast["can_id"] & CAN_ERR_BUSERROR) != 0)
        can_id = np.where(error, 0, fast["can_id"] & 0x1FFFFFFF)
        no = np.zeros(nf, dtype=bool)
        return Frames(
            fast["timestamp"],
            can_id,
            fast["extended"] | error,
            no,
            error,
            fast["length"],
            fast["data"],
            no,
            no,
            no,
        )
    width = max([8] + [len(m.data or b"") for _, m in slow])
    line = np.concatenate([fast_lines, np.array([i for i, _ in slow], dtype=np.int64)])
    order = np.argsort(line, kind="stable")
    data = np.zeros((nf + ns, width), dtype=np.uint8)
    data[:nf, :8] = fast["data"]
    ts = np.concatenate([fast["timestamp"], [m.timestamp for _, m in slow]])
    can_id = np.concatenate([fast["can_id"] & 0x1FFFFFFF, np.zeros(ns, np.int64)])
    extended = np.concatenate([fast["extended"], np.zeros(ns, bool)])
    remote = np.zeros(nf + ns, dtype=bool)
    error = np.zeros(nf + ns, dtype=bool)
    # python-can makes an error frame of an id with the error and bus-error flags.
    error[:nf] = ((fast["can_id"] & CAN_ERR_FLAG) != 0) & ((fast["can_id"] & CAN_ERR_BUSERROR) != 0)
    can_id[:nf][error[:nf]] = 0  # as python-can's error Message: id 0, extended
    extended[:nf][error[:nf]] = True
    length = np.concatenate([fast["length"], np.zeros(ns, np.int64)])
    fd, brs, esi = (np.zeros(nf + ns, dtype=bool) for _ in range(3))
    for k, (_, m) in enumerate(slow, start=nf):
        can_id[k], extended[k] = m.arbitration_id, m.is_extended_id
        remote[k], error[k] = m.is_remote_frame, m.is_error_frame
        fd[k], brs[k], esi[k] = m.is_fd, m.bitrate_switch, m.error_state_indicator
        payload = b"" if m.is_remote_frame or m.data is None else bytes(m.data)
        length[k] = len(payload)
        data[k, : len(payload)] = np.frombuffer(payload, dtype=np.uint8)
    return Frames(
        ts[order],
        can_id[order],
        extended[order],
        remote[order],
        error[order],
        length[order],
        data[order],
        fd[order],
        brs[order],
        esi[order],
    )
