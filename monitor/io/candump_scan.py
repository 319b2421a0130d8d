"""The numba passes of the bulk candump reader (``monitor.io.candump_bulk``): one finds each
line's bounds, its two spaces and its ``#`` and whether it has the plain form; the other turns
the fields of the plain lines into timestamp, id and data bytes (hex by table lookup), with
timestamps correctly rounded as python-can's ``float()`` rounds them.
"""

from __future__ import annotations

import numpy as np

from monitor.io.candump import MAX_TIMESTAMP_DIGITS, MAX_TIMESTAMP_S
from monitor.jit import jit

_HEX = np.full(256, -1, dtype=np.int16)
for _i, _c in enumerate(b"0123456789abcdef"):
    _HEX[_c] = _i
    _HEX[bytes([_c]).upper()[0]] = _i


_POW10 = np.array([float(10**k) for k in range(23)])  # exact doubles up to 1e22


@jit(aot=True)
def scan_lines(buf):  # pragma: no cover - numba
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


def parse_fast(buf, starts, ends, pos) -> tuple[dict[str, np.ndarray], np.ndarray]:
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
