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


class PumpRule:
    """The pump rule's state over a run of rows (see the module)."""

    def __init__(self, model: PumpModel, cols: PumpColumns) -> None:
        self.model = model
        self.cols = cols
        c = model.counting
        self._open, self._step, self._steady = c.open_pct, c.step_pct, c.steady_n
        self._margin, self._min_flow = c.margin_bar, c.min_flow_lpm
        self._block_n, self._blocks = c.block_n, c.blocks
        law = model.law
        self._a, self._b, self._c = law.flow_coef, law.pp_coef, law.offset_bar
        n = len(cols.spool)
        self._last = [math.nan] * n
        self._since = [0] * n
        self._sum = 0.0
        self._n = 0
        self._ring: list[float] = []  # the last ``blocks`` block sums
        self._starts: list[float] = []  # and the row time each began at
        self._t0 = math.nan
        # Per section: the residual's sum and count over the counted samples it was closed
        # in, this block's and the window's blocks'.
        self._shut = [False] * n
        self._csum = [0.0] * n
        self._cn = [0] * n
        self._cring: list[tuple[list[float], list[int]]] = []
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
        return self._starts[0] if self._starts else math.nan

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
        cols = self.cols
        steady = True
        for k, i in enumerate(cols.spool):
            s = row[i]
            # A step (or a missing command: NaN compares false) restarts the steady count.
            if abs(s - self._last[k]) <= self._step:
                self._since[k] += 1
            else:
                self._since[k] = 0
            self._last[k] = s
            steady = steady and self._since[k] >= self._steady
        if not steady:
            return None
        flow = 0.0
        pls = 0.0
        n_open = 0
        shut = self._shut
        for k, i in enumerate(cols.spool):
            s = row[i]
            flow += row[cols.qp[k]]
            shut[k] = False
            if s > self._open:
                n_open += 1
                pls = max(pls, row[cols.pa[k]])
            elif s < -self._open:
                n_open += 1
                pls = max(pls, row[cols.pb[k]])
            else:
                shut[k] = True
        pp = row[cols.pp]
        deficit = pls + self._margin - pp
        if not n_open or not flow > self._min_flow or not math.isfinite(deficit + flow):
            return None
        return flow, pp, deficit

    def tick(self, row: Sequence[float]) -> bool:
        """One row (a list: ``ndarray.tolist()``); True when the state changed."""
        got = self.sample(row)
        if got is None:
            return False
        flow, pp, deficit = got
        if self._n == 0:
            self._t0 = row[0]
        r = deficit - (self._a * flow + self._b * pp + self._c)
        self._sum += r
        self._n += 1
        self.counted += 1
        for k, shut in enumerate(self._shut):
            if shut:
                self._csum[k] += r
                self._cn[k] += 1
        if self._n < self._block_n:
            return False
        return self._block_end()

    def _block_end(self) -> bool:
        ring = self._ring
        ring.append(self._sum)
        self._starts.append(self._t0)
        self._cring.append((self._csum, self._cn))
        if len(ring) > self._blocks:
            del ring[0], self._starts[0], self._cring[0]
        n = len(self._shut)
        self._sum, self._n, self._csum, self._cn = 0.0, 0, [0.0] * n, [0] * n
        if len(ring) < self._blocks:
            return False
        self.stat_bar = sum(ring) / (self._blocks * self._block_n)
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
        need = MIN_CLOSED_SHARE * self._blocks * self._block_n
        best, best_mean, told = None, CLEAR_SHARE * threshold, True
        for k, name in enumerate(self.cols.names):
            n = sum(c[1][k] for c in self._cring)
            if n < need:
                told = False
                continue
            mean = sum(c[0][k] for c in self._cring) / n
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
