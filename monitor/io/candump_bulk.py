"""candump -L logs read in bulk: the whole file into numpy arrays of frames, no per-line Python.
The one candump parser: ``monitor detect`` takes the arrays, ``read_candump`` (replay onto a
bus) the messages made of them.

python-can's CanutilsLogReader builds one ``can.Message`` per line, about 10 us each, and is
lenient with malformed lines.  Here the file is one byte array: a numba pass
finds each line's bounds, its two spaces and its ``#``, a second one turns the fields of
the plain lines into timestamp, id and data bytes (hex by table lookup).  Timestamps are
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
    MAX_TIMESTAMP_DIGITS,
    MAX_TIMESTAMP_S,
    line_problem,
    nul_line,
    skip_odd_line,
    too_long_line,
)
from monitor.jit import jit

_HEX = np.full(256, -1, dtype=np.int16)
for _i, _c in enumerate(b"0123456789abcdef"):
    _HEX[_c] = _i
    _HEX[bytes([_c]).upper()[0]] = _i


_POW10 = np.array([float(10**k) for k in range(23)])  # exact doubles up to 1e22


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
    starts, ends, sp1, sp2, hs, ok = _scan_lines(buf)
    fast = np.flatnonzero(ok)
    pos = {"sp1": sp1[fast], "sp2": sp2[fast], "hash": hs[fast]}
    fields, good = _parse_fast(buf, starts[fast], ends[fast], pos)
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


@jit(aot=True)
def _scan_lines(buf):  # pragma: no cover - numba
    """One pass over the bytes: per line its bounds (a trailing CR excluded), the positions
    of its first two spaces and first '#', and whether it has the plain form
    ``(TS) IFACE ID#DATA``: exactly two single spaces, one '#', no other control or
    non-ASCII byte, an id of 3 or 8 and data of 0-16 characters (even)."""
    n = buf.shape[0]
    cap = 1
    for i in range(n):
        if buf[i] == 10:
            cap += 1
    starts = np.empty(cap, np.int64)
    ends = np.empty(cap, np.int64)
    sp1 = np.zeros(cap, np.int64)
    sp2 = np.zeros(cap, np.int64)
    hs = np.zeros(cap, np.int64)
    ok = np.zeros(cap, np.bool_)
    m = 0
    s = 0
    while s < n:
        e = s
        while e < n and buf[e] != 10:
            e += 1
        nxt = e + 1
        if e > s and buf[e - 1] == 13:
            e -= 1
        nsp = 0
        nh = 0
        odd = False
        for k in range(s, e):
            c = buf[k]
            if c == 32:
                if nsp == 0:
                    sp1[m] = k
                elif nsp == 1:
                    sp2[m] = k
                nsp += 1
            elif c == 35:
                if nh == 0:
                    hs[m] = k
                nh += 1
            elif c < 32 or c > 126:
                odd = True
        starts[m] = s
        ends[m] = e
        good = nsp == 2 and nh == 1 and not odd and e - s >= 8
        if good:
            a, b, h = sp1[m], sp2[m], hs[m]
            idl, dl = h - b - 1, e - h - 1
            good = (
                buf[s] == 40
                and buf[a - 1] == 41
                and a >= s + 4
                and b >= a + 2
                and h > b
                and (idl == 3 or idl == 8)
                and 0 <= dl <= 16
                and dl % 2 == 0
            )
        ok[m] = good
        m += 1
        s = nxt
    return starts[:m], ends[:m], sp1[:m], sp2[:m], hs[:m], ok[:m]


def _parse_fast(buf, starts, ends, pos) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Fields of plain lines; ``good`` is False for a line whose characters turn out not to
    fit (it is then read the slow way, which names it if it is malformed)."""
    width = int((pos["sp1"] - starts - 2).max()) if starts.size else 1
    ts, exact, ts_chars, can_id, length, data, good = _fields(
        buf,
        starts,
        ends,
        pos["sp1"],
        pos["sp2"],
        pos["hash"],
        _HEX,
        _POW10,
        max(width, 1),
        MAX_TIMESTAMP_DIGITS,
    )
    # Timestamps of 2^53 and more digits: numpy's bytes -> float64, correctly rounded as
    # python-can's float() (the zero padding of shorter ones is not part of an "S" string).
    slow = good & ~exact
    if slow.any():
        ts[slow] = ts_chars[slow].view(f"S{ts_chars.shape[1]}").ravel().astype(np.float64)
    # Out of range: read the slow way, where line_problem names it.
    good &= ts <= MAX_TIMESTAMP_S
    out = {
        "timestamp": ts,
        "can_id": can_id,
        "extended": (pos["hash"] - pos["sp2"] - 1) > 3,
        "length": length,
        "data": data,
    }
    return out, good


@jit(aot=True, fastmath=False)  # the timestamp division must round as IEEE says, not reassociate
def _fields(buf, starts, ends, sp1, sp2, hs, hexval, pow10, width, max_whole):  # pragma: no cover
    """Per plain line: timestamp, id, data, and whether its characters fit (a timestamp of
    more than ``max_whole`` digits before the point does not).

    A timestamp whose digits N (the point dropped) are below 2^53 is N / 10^k with N and
    10^k (k <= 22) exact doubles, and IEEE division rounds the exact quotient once: the
    correctly rounded value of the decimal string, bit-identical to Python's float().
    Longer ones (candump's 10 + 6 digits are far below) are flagged for numpy."""
    m = starts.shape[0]
    ts = np.zeros((m, width), np.uint8)
    value = np.full(m, np.nan)
    exact = np.zeros(m, np.bool_)
    can_id = np.zeros(m, np.int64)
    length = np.zeros(m, np.int64)
    data = np.zeros((m, 8), np.uint8)
    good = np.ones(m, np.bool_)
    for r in range(m):
        # timestamp: digits, exactly one '.', neither first nor last
        a, b = starts[r] + 1, sp1[r] - 1
        dots = 0
        digits = 0
        frac = 0
        num = 0
        for k in range(a, b):
            c = buf[k]
            if c == 46:
                dots += 1
                if k == a or k == b - 1:
                    good[r] = False
            elif c < 48 or c > 57:
                good[r] = False
            else:
                digits += 1
                frac += dots
                if digits <= 18:  # fits int64
                    num = num * 10 + (c - 48)
            ts[r, k - a] = c
        if dots != 1 or digits - frac > max_whole:
            good[r] = False
        elif digits <= 18 and num < 9007199254740992 and frac < 23:  # N < 2^53
            value[r] = num / pow10[frac]
            exact[r] = True
        v = 0
        for k in range(sp2[r] + 1, hs[r]):
            d = hexval[buf[k]]
            if d < 0:
                good[r] = False
            v = (v << 4) | (d & 15)
        can_id[r] = v
        nb = (ends[r] - hs[r] - 1) // 2
        length[r] = nb
        for j in range(nb):
            hi = hexval[buf[hs[r] + 1 + 2 * j]]
            lo = hexval[buf[hs[r] + 2 + 2 * j]]
            if hi < 0 or lo < 0:
                good[r] = False
            data[r, j] = ((hi & 15) << 4) | (lo & 15)
    return value, exact, ts, can_id, length, data, good


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
