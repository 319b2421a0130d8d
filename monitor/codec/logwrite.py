"""Writing a Recording as a candump log: every DBC message at its cycle time, with valid
alive counters and CRCs (`monitor encode`, the simulator's .log output)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from monitor.codec.frames import FrameCodec
from monitor.errors import InputFileError
from monitor.io.candump import DEFAULT_START_TIME_S, format_line
from monitor.io.recording import Recording


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
                buf.append(
                    format_line(stamps[i], channel, info.frame_id, info.is_extended_id, data)
                )
                counts[name] += 1
                if len(buf) >= 4096:
                    fh.writelines(buf)
                    buf.clear()
            fh.writelines(buf)
    except OSError as exc:
        raise InputFileError(f"{p}: cannot write: {exc.strerror or exc}") from None
    return counts
