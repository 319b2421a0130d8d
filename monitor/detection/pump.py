"""The pump rule: the shared load-sensing pump judged on its own, one row at a time.

A worn pump makes its leak up with displacement, so every section still gets its flow and
no loop's model (PP an input) sees it; what it costs is the pump's margin (the law in
``monitor.model.pumplaw``).  ``PumpRule.tick`` reads one 100 Hz row of the machine (the
daemon's row layout, ``monitor.config.layout``), decides whether the row counts (a section
open, every spool steady, flow drawn), adds the law's residual to the current block, and at
the end of a block compares the mean residual of the last window with the model's threshold:
``fault`` (``pump_wear``) above it, ``normal`` again below half of it, ``inactive`` until the
first window is full or when the rule is off.  A worn pump is short of margin whichever
sections are open; a loop's own fault that costs margin (a leaking boom piston drawing the
pump to its limit) is short only while its section is open.  So the excess must show in the
window's samples with each section closed too (those of a section closed for at least a
fifth of the window): where one section's closed samples show less than half the threshold
the excess is that section's (``carried_by``) and the pump is not in fault; a section
closed for less than that cannot be told apart, and the state stays as it was.  The daemon
ticks it after the loops (a few float operations per section; lists, no numpy per row);
``monitor detect --pump`` and
``monitor eval-sim --machine`` tick the same class over a recording's rows (``judge_rows``),
so the live and the offline events are the same.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from monitor.detection.alarm import State
from monitor.detection.decision import wall_time
from monitor.model.pumplaw import PumpModel

PUMP = "pump"
PUMP_FAULT = "pump_wear"
#: Back to normal below this share of the threshold (no flapping on a window at the edge).
CLEAR_SHARE = 0.5
#: A section's share of the window closed that can say whether the excess is its own.
MIN_CLOSED_SHARE = 0.2


@dataclass(frozen=True)
class PumpColumns:
    """Where a row (``[t, *columns]``) holds the pump's PP and each section's spool
    command, feeding ports and flow (indices into the row, t at 0)."""

    pp: int
    spool: tuple[int, ...]
    pa: tuple[int, ...]
    pb: tuple[int, ...]
    qp: tuple[int, ...]
    names: tuple[str, ...] = ()  # the sections' (loops') names, in order

    @classmethod
    def of(
        cls,
        columns: Sequence[str],
        pp: str,
        sections: Sequence[dict[str, str]],
        names: Sequence[str] = (),
    ) -> PumpColumns:
        """From the row's column names: ``pp`` and per section its ``SpoolCmd``, ``PA``,
        ``PB`` and ``QP`` signal names (a ``KeyError`` naming the one missing)."""

        def at(name: str) -> int:
            if name not in columns:
                raise KeyError(name)
            return 1 + list(columns).index(name)

        return cls(
            at(pp),
            tuple(at(s["SpoolCmd"]) for s in sections),
            tuple(at(s["PA"]) for s in sections),
            tuple(at(s["PB"]) for s in sections),
            tuple(at(s["QP"]) for s in sections),
            tuple(names) or tuple(f"section {k + 1}" for k in range(len(sections))),
        )


@dataclass
class PumpTick:
    """What a row did to the rule: ``changed`` the state; ``stat_bar`` the window's mean
    residual (NaN before the first full window)."""

    t_s: float
    state: State
    stat_bar: float
    changed: bool
    raised: bool


class _Spools:
    """How long each section's spool command has been steady (no step over ``step_pct``)."""

    def __init__(self, n: int, step_pct: float, steady_n: int) -> None:
        self.step, self.steady_n = step_pct, steady_n
        self.last = [math.nan] * n
        self.since = [0] * n

    def steady(self, row: Sequence[float], spool: tuple[int, ...]) -> bool:
        """Every spool steady for ``steady_n`` rows (every row must pass here, in order)."""
        ok = True
        for k, i in enumerate(spool):
            s = row[i]
            # A step (or a missing command: NaN compares false) restarts the steady count.
            if abs(s - self.last[k]) <= self.step:
                self.since[k] += 1
            else:
                self.since[k] = 0
            self.last[k] = s
            ok = ok and self.since[k] >= self.steady_n
        return ok


class _Window:
    """The counted residuals in blocks of ``block_n``, the last ``blocks`` of them: each
    block's sum, the row time it began at, and per section the sum and count of the
    residuals of the samples that section was closed in."""

    def __init__(self, n: int, block_n: int, blocks: int) -> None:
        self.n, self.block_n, self.blocks = n, block_n, blocks
        self.block = self._empty()
        self.full: list[tuple[float, float, list[float], list[int], int]] = []

    def _empty(self) -> tuple[list[float], list[float], list[int], list[int]]:
        # ([sum, t0], closed sums, closed counts, [count])
        return [0.0, math.nan], [0.0] * self.n, [0] * self.n, [0]

    def add(self, r: float, t_s: float, shut: list[bool]) -> bool:
        """One counted residual; True when it ends a block and the window is full."""
        head, csum, cn, count = self.block
        if count[0] == 0:
            head[1] = t_s
        head[0] += r
        count[0] += 1
        for k, closed in enumerate(shut):
            if closed:
                csum[k] += r
                cn[k] += 1
        if count[0] < self.block_n:
            return False
        self.full.append((head[0], head[1], csum, cn, count[0]))
        if len(self.full) > self.blocks:
            del self.full[0]
        self.block = self._empty()
        return len(self.full) == self.blocks

    @property
    def mean(self) -> float:
        return sum(b[0] for b in self.full) / sum(b[4] for b in self.full)

    @property
    def start_s(self) -> float:
        return self.full[0][1] if self.full else math.nan

    def closed(self, k: int) -> tuple[float, int]:
        """Section ``k``'s closed samples of the window: (residual sum, count)."""
        return sum(b[2][k] for b in self.full), sum(b[3][k] for b in self.full)


class PumpRule:
    """The pump rule's state over a run of rows (see the module)."""

    def __init__(self, model: PumpModel, cols: PumpColumns) -> None:
        self.model = model
        self.cols = cols
        c = model.counting
        n = len(cols.spool)
        self._spools = _Spools(n, c.step_pct, c.steady_n)
        self._window = _Window(n, c.block_n, c.blocks)
        self._shut = [False] * n  # per section: closed in the last counted row
        #: Whose the excess over the threshold is: ``pump``, a section, None (none, or
        #: cannot be told).
        self.carried_by: str | None = None
        self.state = State.INACTIVE
        self.stat_bar = math.nan
        self.counted = 0  # counted samples so far
        self.windows = 0  # statistics computed (one per block once the window is full)
        self.alarms = 0

    @property
    def window_start_s(self) -> float:
        """Row time at which the current window's first counted sample came."""
        return self._window.start_s

    @property
    def level(self) -> float:
        """The statistic over the threshold (1 = alarm; NaN: no window yet, or off)."""
        return self.stat_bar / self.threshold_bar

    @property
    def threshold_bar(self) -> float:
        return self.model.threshold_bar if self.model.threshold_bar is not None else math.nan

    def sample(self, row: Sequence[float]) -> tuple[float, float, float] | None:
        """(total flow L/min, PP bar, margin deficit bar) of a row that counts, else None;
        updates the spools' steadiness (every row must pass here, in order)."""
        cols, c = self.cols, self.model.counting
        if not self._spools.steady(row, cols.spool):
            return None
        flow = 0.0
        pls = 0.0
        n_open = 0
        shut, open_pct = self._shut, c.open_pct
        for k, i in enumerate(cols.spool):
            s = row[i]
            flow += row[cols.qp[k]]
            shut[k] = False
            if s > open_pct:
                n_open += 1
                pls = max(pls, row[cols.pa[k]])
            elif s < -open_pct:
                n_open += 1
                pls = max(pls, row[cols.pb[k]])
            else:
                shut[k] = True
        pp = row[cols.pp]
        deficit = pls + c.margin_bar - pp
        if not n_open or not flow > c.min_flow_lpm or not math.isfinite(deficit + flow):
            return None
        return flow, pp, deficit

    def tick(self, row: Sequence[float]) -> bool:
        """One row (a list: ``ndarray.tolist()``); True when the state changed."""
        got = self.sample(row)
        if got is None:
            return False
        flow, pp, deficit = got
        self.counted += 1
        if not self._window.add(deficit - self.model.law.deficit(flow, pp), row[0], self._shut):
            return False
        self.stat_bar = self._window.mean
        self.windows += 1
        self.carried_by = self._carried_by()
        return self._decide()

    def _carried_by(self) -> str | None:
        """Whose the window's excess is: ``PUMP`` when the samples with each section closed
        show it too (at least half the threshold, each section closed for a fifth of the
        window), the section whose closed samples show less than that, or None: no excess
        over the threshold, or a section that was hardly ever closed (it cannot be told)."""
        threshold = self.model.threshold_bar
        if threshold is None or not self.stat_bar > threshold:
            return None
        need = MIN_CLOSED_SHARE * self.model.counting.window_n
        best, best_mean, told = None, CLEAR_SHARE * threshold, True
        for k, name in enumerate(self.cols.names):
            total, n = self._window.closed(k)
            if n < need:
                told = False
                continue
            mean = total / n
            if mean < best_mean:
                best, best_mean = name, mean
        return best if best is not None else PUMP if told else None

    def _decide(self) -> bool:
        threshold = self.model.threshold_bar
        was = self.state
        if threshold is None:
            return False  # off: inactive, the model file says why
        carried = self.carried_by
        if carried == PUMP:
            self.state = State.FAULT
        # The first window, a section's excess (not the pump's), or well below: normal; else
        # (near the threshold, or a section that cannot be told apart) as it was.
        elif (
            self.state is State.INACTIVE
            or carried is not None
            or self.stat_bar < CLEAR_SHARE * threshold
        ):
            self.state = State.NORMAL
        if self.state is State.FAULT and was is not State.FAULT:
            self.alarms += 1
        return self.state is not was

    def event(self, t_s: float, time: str | None = None, origin_s: float = 0.0) -> dict[str, Any]:
        """The event line of the current state (``loop: pump``) at row time ``t_s``;
        ``t`` and ``window_from_t`` from ``origin_s`` (the first row)."""
        fault = self.state is State.FAULT
        return {
            "t": round(float(t_s - origin_s), 6),
            "time": time,
            "loop": PUMP,
            "state": self.state.label,
            "fault": PUMP_FAULT if fault else None,
            "margin_residual_bar": _rounded(self.stat_bar),
            "threshold_bar": _rounded(self.threshold_bar),
            "counted_s": round(self.counted * 0.01, 2),
            "window_from_t": _rounded(self.window_start_s - origin_s),
            "carried_by": self.carried_by,
        }


def _rounded(x: float) -> float | None:
    return round(float(x), 5) if math.isfinite(x) else None


@dataclass
class PumpDetection:
    """The pump rule over a recording: its events and summary (``monitor detect --pump``)."""

    events: list[dict[str, Any]]
    summary: dict[str, Any]


def judge_rows(
    model: PumpModel, cols: PumpColumns, rows: np.ndarray, start_time_s: float | None = None
) -> PumpDetection:
    """``PumpRule`` ticked over ``rows`` (``[t, *columns]``; events' ``t`` from the first
    row, ``time`` the wall clock when the log time of the first row is given)."""
    rule = PumpRule(model, cols)
    events = []
    first_alarm = None
    peak = -math.inf
    for row in rows.tolist():
        if rule.tick(row):
            t_s = row[0] - rows[0, 0]
            events.append(rule.event(row[0], wall_time(t_s, start_time_s), rows[0, 0]))
            if rule.state is State.FAULT and first_alarm is None:
                first_alarm = events[-1]["t"]
        if rule.stat_bar > peak:
            peak = rule.stat_bar
    judged = math.isfinite(rule.stat_bar) and model.on
    verdict = "fault" if first_alarm is not None else "healthy" if judged else "not_judged"
    why = None
    if not model.on:
        why = f"the pump rule is off: {model.off_reason}"
    elif not judged:
        window_s = model.counting.window_n * 0.01
        why = f"{rule.counted * 0.01:.1f} s of steady open flow, the window needs {window_s:g} s"
    summary = {
        "loop": PUMP,
        "alarm": first_alarm is not None,
        "first_alarm_t": first_alarm,
        "fault": PUMP_FAULT if first_alarm is not None else None,
        "verdict": verdict,
        "not_judged_why": why,
        "max_margin_residual_bar": _rounded(peak),
        "threshold_bar": _rounded(rule.threshold_bar),
        "counted_s": round(rule.counted * 0.01, 2),
    }
    return PumpDetection(events, summary)


def counted_samples(model: PumpModel, cols: PumpColumns, rows: np.ndarray) -> np.ndarray:
    """(total flow, PP, deficit) of every row of ``rows`` that counts (``PumpRule.sample``,
    the rule's own choice of samples): what ``monitor train --pump`` fits the law on."""
    rule = PumpRule(model, cols)
    got = [s for row in rows.tolist() if (s := rule.sample(row)) is not None]
    return np.array(got, dtype=float).reshape(-1, 3)


def window_stats(model: PumpModel, cols: PumpColumns, rows: np.ndarray) -> tuple[np.ndarray, int]:
    """The rule's statistic at every block end over ``rows`` (the values its threshold is
    compared with) and the counted samples."""
    rule = PumpRule(model, cols)
    out = []
    for row in rows.tolist():
        n = rule.windows
        rule.tick(row)
        if rule.windows != n:
            out.append(rule.stat_bar)
    return np.array(out, dtype=float), rule.counted
