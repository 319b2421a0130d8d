"""The machine's finding: which of several alarms of one machine names the fault.

Loops on one pump feel each other: a stick whose piston leaks moves PP, a boom spool that
leaks shifts the flow the swing gets, and a neighbour's model may end in an alarm of its own
some minutes later.  Each loop still raises its own alarm (its MON_Alarm is its own
evidence, never suppressed); the machine's finding says which one a service engineer should
look at first:

- the **pump**, when the pump rule (``monitor.detection.pump``) is in fault: the loops whose
  alarm came after the pump's window began (the margin was already off the law then) are
  *explained* by it;
- else the **loop whose alarm came first**; alarms within ``TIE_S`` of each other are one
  instant, and the stronger evidence (the higher level, statistic over threshold) names;
- the loops that alarmed later are *secondary*: a consequence to be checked, not the finding.

When every alarm has cleared the next alarm starts a new finding.  ``MachineFinding`` is fed
alarm by alarm in time order: the daemon feeds it at each raise and clear
(``monitor.live.machine``), ``monitor eval-sim --machine`` feeds it the run's first alarm of
each loop and of the pump (``finding_of``); the same rule both ways.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from monitor.detection.pump import PUMP

#: Alarms raised within this many seconds of each other came at one instant: the stronger
#: evidence names.  A loop's J reaches its threshold over its window (1-3 s), so a second's
#: order says little about which fault came first.
TIE_S = 1.0


@dataclass(frozen=True)
class Alarm:
    """One raised alarm: its ``source`` (a loop's name or ``pump``), when (``t_s``), its
    evidence (``level``: statistic over threshold) and, for the pump, when the window its
    statistic rests on began (``since_s``)."""

    source: str
    t_s: float
    level: float = math.nan
    since_s: float | None = None


@dataclass
class Finding:
    named: str | None = None
    t_s: float | None = None  # the named alarm's raise
    secondary: list[str] = field(default_factory=list)
    explained: list[str] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        return {
            "named": self.named,
            "named_t": None if self.t_s is None else round(self.t_s, 6),
            "secondary": list(self.secondary),
            "explained_by_pump": list(self.explained),
        }


class MachineFinding:
    """The finding over the alarms raised since every alarm last cleared."""

    def __init__(self, tie_s: float = TIE_S) -> None:
        self.tie_s = tie_s
        self.active: dict[str, Alarm] = {}  # raised and not cleared
        self.episode: dict[str, Alarm] = {}  # raised in this episode, first raise each
        self.finding = Finding()

    def raised(self, alarm: Alarm) -> bool:
        """An alarm raised; True when the finding changed."""
        self.active[alarm.source] = alarm
        self.episode.setdefault(alarm.source, alarm)
        return self._decide()

    def cleared(self, source: str) -> bool:
        """An alarm cleared; when none is left the next one starts afresh.  True when the
        finding changed (to none)."""
        self.active.pop(source, None)
        if self.active or not self.episode:
            return False
        self.episode.clear()
        self.finding = Finding()
        return True

    def _decide(self) -> bool:
        was = self.finding.as_dict()
        self.finding = decide(self.episode.values(), self.tie_s)
        return self.finding.as_dict() != was


def decide(alarms: Iterable[Alarm], tie_s: float = TIE_S) -> Finding:
    """The finding of one episode's alarms (each source's first raise)."""
    alarms = sorted(alarms, key=lambda a: a.t_s)
    if not alarms:
        return Finding()
    pump = next((a for a in alarms if a.source == PUMP), None)
    loops = [a for a in alarms if a.source != PUMP]
    if pump is not None:
        start = pump.t_s if pump.since_s is None else pump.since_s
        explained = [a.source for a in loops if a.t_s >= start]
        before = [a.source for a in loops if a.t_s < start]
        return Finding(PUMP, pump.t_s, before, explained)
    first = loops[0].t_s
    tied = [a for a in loops if a.t_s - first <= tie_s]
    named = max(tied, key=lambda a: (a.level if a.level == a.level else -math.inf, -a.t_s))
    return Finding(named.source, named.t_s, [a.source for a in loops if a is not named])


def finding_of(alarms: Iterable[Alarm], tie_s: float = TIE_S) -> Finding:
    """``MachineFinding`` fed ``alarms`` in time order (none clearing): the finding at the
    end, as the daemon has it after the last of them."""
    mf = MachineFinding(tie_s)
    for a in sorted(alarms, key=lambda a: a.t_s):
        mf.raised(a)
    return mf.finding
