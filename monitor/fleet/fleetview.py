"""What the fleet web page shows, computed from the results (no HTML here).

Per machine: its state (the newest log's verdict, or ``wearing?`` when a healthy machine's
drift from commissioning reached 2 x), the fault or sensor it is named with, since which
log, the first warning and what to do.  Across the fleet: every alarm episode (the alarm
list) and the DM1 codes grouped by SPN/FMI and period.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import PurePosixPath
from typing import Any

from monitor.fleet.actions import (
    STATE_ACTIONS,
    fault_action,
    sensor_action,
    sensor_label,
    signal_meaning,
)
from monitor.fleet.episodes import MachineFault, machine_fault, row_episodes
from monitor.fleet.health import (
    DRIFT_FLAG,
    FirstWarning,
    drift,
    first_warning,
    health_index,
    log_day,
)
from monitor.fleet.loops import series_name, split


def log_name(row: dict[str, Any]) -> str:
    """A log's short name on the page: its file stem (``day03-1``)."""
    return PurePosixPath(row["log"]).stem


def period(row: dict[str, Any]) -> str:
    """The period a log belongs to: its day (``day 03``) when the file name has one, else
    the date of its first event's wall clock, else ``-``."""
    d = log_day(row)
    if d is not None:
        return f"day {d:02d}"
    return row.get("_date") or "-"


def alarm_id(row: dict[str, Any], ep: dict[str, Any]) -> str:
    """An alarm's key in the acknowledgement file: log, (a whole machine's) loop, kind and
    start (stable across reruns of the same log)."""
    loop = f"{row['loop']}:" if row.get("loop") else ""
    return f"{row['log']}#{loop}{ep['kind']}@{ep['start_t']:.2f}"


def page_name(machine: str, loop: str | None) -> str:
    """A machine's page (``machine-M01.html``), or its loop's (``machine-M01-stick.html``)."""
    return f"machine-{machine}.html" if loop is None else f"machine-{machine}-{loop}.html"


@dataclass(frozen=True)
class Span:
    """When an alarm episode was active, in seconds into its log."""

    start_t: float
    end_t: float
    duration_s: float
    open: bool  # still active at the end of the log


@dataclass(frozen=True)
class TroubleCode:
    """The J1939 DM1 trouble code an episode was sent with."""

    spn: int
    fmi: int


@dataclass
class Alarm:
    """One alarm episode of the alarm list."""

    id: str
    machine: str
    log: str  # short name
    period: str
    kind: str  # fault or sensor_fault
    name: str  # fault name or sensor signal
    check: str | None
    span: Span
    code: TroubleCode
    votes: dict[str, int]
    what: str  # e.g. "piston seal suspected" or "QP frozen"
    action: str
    loop: str | None = None  # a whole machine's loop

    @property
    def page(self) -> str:
        return page_name(self.machine, self.loop)

    @property
    def label(self) -> str:
        """``M01``, or a whole machine's loop: ``M01 stick``."""
        return series_name(self.machine, self.loop)

    @property
    def votes_text(self) -> str:
        total = sum(self.votes.values())
        if not total:
            return ""
        parts = sorted(self.votes.items(), key=lambda kv: -kv[1])
        return ", ".join(f"{k} {100 * v / total:.0f} %" for k, v in parts)


def _alarm(row: dict[str, Any], ep: dict[str, Any]) -> Alarm:
    if ep["kind"] == "fault":
        what, action = fault_action(ep["name"])
    else:
        what, action = sensor_label(ep["name"], ep.get("check")), sensor_action(ep.get("check"))[1]
    return Alarm(
        alarm_id(row, ep),
        row["machine"],
        log_name(row),
        period(row),
        ep["kind"],
        ep["name"],
        ep.get("check"),
        Span(ep["start_t"], ep["end_t"], ep["duration_s"], bool(ep.get("open"))),
        TroubleCode(ep["spn"], ep["fmi"]),
        ep.get("votes") or {},
        what,
        action,
        row.get("loop"),
    )


@dataclass
class MachineView:
    machine: str
    rows: list[dict[str, Any]]
    state: str  # fault, sensor_fault, wearing?, healthy, not_judged, error
    finding: str  # the fault or sensor by name, "" when none
    evidence: str  # why that name (isolation votes), "" when none
    since: str  # the log the finding was first seen at, "" when none
    last_seen: str
    what_to_do: str
    warning: FirstWarning
    fault: MachineFault
    index: float | None  # the newest judged log's health index
    drift: float | None
    alarms: list[Alarm] = field(default_factory=list)
    loop: str | None = None  # a whole machine's loop: this view is that loop's

    @property
    def page(self) -> str:
        return page_name(self.machine, self.loop)

    @property
    def name(self) -> str:
        """``M01``, or a whole machine's loop: ``M01 stick``."""
        return series_name(self.machine, self.loop)


def _finding(rows: list[dict[str, Any]], alarms: list[Alarm], fault: MachineFault, state: str):
    """(finding, evidence, since, last seen, action): of the kind of the machine's state
    (fault or sensor fault) when it has such episodes, else of the newest episode's kind."""
    if not alarms:
        if fault.name is None:
            return "", "", "", "", ""
        # Older results without episodes: the rows' own fault names.
        what, action = fault_action(fault.name)
        named = [log_name(r) for r in rows if r.get("alarm") and r.get("fault")]
        return f"{fault.name}: {what}", "", named[0], named[-1], action
    newest = alarms[-1]
    kinds = [a for a in alarms if a.kind == state]
    newest = kinds[-1] if kinds else newest
    if newest.kind == "fault":
        what, action = fault_action(fault.name)
        same = [a for a in alarms if a.kind == "fault"]
        return (f"{fault.name}: {what}", fault.evidence, same[0].log, same[-1].log, action)
    same = [a for a in alarms if a.kind == "sensor_fault" and a.name == newest.name]
    checks = [a for a in same if a.check]
    check = checks[-1].check if checks else None
    return (
        sensor_label(newest.name, check),
        signal_meaning(newest.name),
        same[0].log,
        same[-1].log,
        sensor_action(check)[1],
    )


def machine_view(
    machine: str, rows: list[dict[str, Any]], k: int = 6, loop: str | None = None
) -> MachineView:
    """One machine's (or its loop's) line of the fleet table (rows in time order)."""
    alarms = [_alarm(r, ep) for r in rows for ep in row_episodes(r)]
    fault = machine_fault(rows)
    for a in alarms:
        if a.kind == "fault" and fault.name is not None and a.name != fault.name:
            # One episode's evidence does not rename the machine: say both, act on the
            # machine's name.
            what, a.action = fault_action(fault.name)
            a.what = f"{a.what} (this episode); the machine: {what}"
    last = rows[-1]
    d = drift(rows)
    if last.get("error"):
        state = "error"
    elif last["verdict"] == "healthy" and d is not None and d >= DRIFT_FLAG:
        state = "wearing?"
    else:
        state = last["verdict"]
    finding, evidence, since, last_seen, action = _finding(rows, alarms, fault, state)
    if state == "fault":
        todo = action or fault_action(None)[1]
    elif state == "sensor_fault":
        todo = action or sensor_action(None)[1]
    elif state == "wearing?":
        todo = STATE_ACTIONS["wearing"]
    elif finding:
        todo = f"{STATE_ACTIONS.get(state, '')}; last alarm at {last_seen}: watch the next logs"
    else:
        todo = STATE_ACTIONS.get(state, "")
    judged = [r for r in rows if health_index(r) is not None and not r.get("error")]
    return MachineView(
        machine,
        rows,
        state,
        finding,
        evidence,
        since,
        last_seen,
        todo,
        first_warning(machine, rows, k),
        fault,
        health_index(judged[-1]) if judged else None,
        d,
        alarms,
        loop,
    )


def fleet_views(per: dict[str, list[dict[str, Any]]], k: int = 6) -> list[MachineView]:
    """Every machine's view (a whole machine's: each loop's), those needing attention
    first (fault, sensor, wearing), a machine's loops in their order."""
    order = {"fault": 0, "sensor_fault": 1, "wearing?": 2, "error": 3, "not_judged": 4}
    views = [
        machine_view(m, part, k, loop)
        for m, rows in per.items()
        for loop, part in split(rows).items()
    ]
    return sorted(views, key=lambda v: (order.get(v.state, 5), v.machine))


@dataclass
class CodeGroup:
    spn: int
    fmi: int
    what: str
    machines: list[str]
    per_period: dict[str, int]  # episodes per period


def _code_meaning(a: Alarm) -> str:
    """What a DM1 code says: the episode's own name (the one it was sent with), never the
    machine's name an episode row adds when they differ."""
    if a.kind == "fault":
        return fault_action(a.name)[0]
    return sensor_label(a.name, a.check)


def code_groups(views: list[MachineView]) -> tuple[list[CodeGroup], list[str]]:
    """Episodes counted per DM1 code (SPN, FMI) and period; the periods in order."""
    groups: dict[tuple[int, int], CodeGroup] = {}
    periods: set[str] = set()
    for v in views:
        for a in v.alarms:
            c = a.code
            g = groups.setdefault(
                (c.spn, c.fmi), CodeGroup(c.spn, c.fmi, _code_meaning(a), [], defaultdict(int))
            )
            if a.label not in g.machines:
                g.machines.append(a.label)
            g.per_period[a.period] += 1
            periods.add(a.period)
    return sorted(groups.values(), key=lambda g: (g.spn, g.fmi)), sorted(periods)
