"""A whole machine on the fleet's pages: its loops' verdicts (and its pump's, ``loop``
``pump``) and the machine's, which names the loop or the pump (``FAULT: stick``,
``FAULT: pump``) by the machine's finding.

A row of logs.parquet with a ``loop`` is one loop of one log (`monitor fleet run` with a
config of several loops); each (machine, loop) is then a series of its own (its health, trend
and alarms, as a one-loop machine's), and a machine's verdict gathers its loops' verdicts
on its newest log.  A loop judged with a model not commissioned on the machine (no
commissioning data, or its training failed) is ``uncommissioned``, never healthy: its
hydraulic alarms are withheld.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

Rows = list[dict[str, Any]]

#: The order of a loop cell's verdicts in a machine's verdict: the worst first.
_SEVERITY = ("fault", "sensor_fault", "error", "not_judged", "uncommissioned", "healthy")


@lru_cache(maxsize=1)
def _shipped_order() -> tuple[str, ...]:
    """The shipped whole machine's loops (config/excavator4.yaml), in its order."""
    from monitor.config.settings import load_config
    from monitor.resources import resource_path

    cfg = load_config(resource_path("config", "excavator4.yaml"))
    return tuple(lc.name for lc in cfg.monitored_loops)


def loop_order(loops: set[str]) -> list[str]:
    """``loops`` as a user thinks of them: the shipped whole machine's order (boom, stick,
    bucket, swing), other names after them, alphabetically."""
    known = _shipped_order()
    return sorted(loops, key=lambda x: (known.index(x) if x in known else len(known), x))


def has_loops(per: dict[str, Rows]) -> bool:
    """Whether any row is one loop of a whole machine's log."""
    return any(r.get("loop") for rows in per.values() for r in rows)


def split(rows: Rows) -> dict[str | None, Rows]:
    """One machine's rows (time order) per loop, loops in :func:`loop_order` (None: the
    rows of logs judged as one loop)."""
    by: dict[str | None, Rows] = defaultdict(list)
    for r in rows:
        by[r.get("loop")].append(r)
    named = loop_order({k for k in by if k is not None})
    return {k: by[k] for k in ([None] if None in by else []) + named}


def series_name(machine: str, loop: str | None) -> str:
    """A series' name on the pages: ``M01`` or ``M01 stick``."""
    return machine if loop is None else f"{machine} {loop}"


def cell(row: dict[str, Any]) -> str:
    """One loop's verdict on one log: fault, sensor_fault, healthy, not_judged, error, or
    uncommissioned (no model of this machine's loop: not judged, or judged with another
    machine's model, its hydraulic alarms withheld)."""
    if row.get("error"):
        return "error"
    if str(row.get("model") or "").startswith("default") and row["verdict"] == "not_judged":
        return "uncommissioned"
    if row["verdict"] == "not_judged":
        return "not_judged"
    if row.get("reference_model") and row["verdict"] != "sensor_fault":
        return "uncommissioned"
    return row["verdict"]


_WORDS = {
    "fault": "FAULT",
    "sensor_fault": "SENSOR FAULT",
    "error": "error",
    "not_judged": "not judged",
    "uncommissioned": "uncommissioned",
    "healthy": "healthy",
}


@dataclass(frozen=True)
class MachineVerdict:
    """A whole machine on its newest log: each loop's verdict, and the machine's."""

    machine: str
    log: str  # the newest log
    cells: dict[str, str]  # loop -> cell()
    state: str  # the worst cell (fault first)
    finding: str | None = None  # the machine's finding on the log: the source it names
    why: dict[str, str] = field(default_factory=dict)  # loop -> why it is not judged

    @property
    def text(self) -> str:
        """``FAULT: stick``, ``SENSOR FAULT: swing``, ``healthy``: each state's loops, the
        worst first (healthy ones said only beside loops not judged).  With several
        alarms the machine's finding names one: ``FAULT: pump (also alarmed: boom)``."""
        if self.state == "healthy":
            return "healthy"
        groups = []
        for state in _SEVERITY:
            named = [loop for loop, c in self.cells.items() if c == state]
            if state == "fault" and self.finding in named and len(named) > 1:
                others = ", ".join(x for x in named if x != self.finding)
                groups.append(f"FAULT: {self.finding} (also alarmed: {others})")
            elif named and not (state == "healthy" and self.state in ("fault", "sensor_fault")):
                groups.append(f"{_WORDS[state]}: {', '.join(named)}")
        return "; ".join(groups)


def machine_verdict(machine: str, rows: Rows) -> MachineVerdict:
    """The machine's verdict on its newest log (rows in time order, a row per loop)."""
    newest = max(r["log"] for r in rows)
    last = {r["loop"]: r for r in rows if r["log"] == newest and r.get("loop")}
    cells = {loop: cell(last[loop]) for loop in loop_order(set(last))}
    state = min(cells.values(), key=_SEVERITY.index) if cells else "not_judged"
    finding = next((r["finding"] for r in last.values() if r.get("finding")), None)
    why = {loop: r["not_judged_why"] for loop, r in last.items() if r.get("not_judged_why")}
    return MachineVerdict(machine, newest, cells, state, finding, why)


def add_findings(rows: Rows) -> None:
    """Each whole machine's log: the machine's finding over its rows' alarms
    (``monitor.detection.machine``, as the daemon and `monitor eval-sim --machine` decide
    it: the pump when its rule is in fault, else the loop whose alarm came first), set on
    every row of the log as ``finding`` (the source named) and ``finding_role`` (the row's
    part: ``named``, ``secondary``, ``explained_by_pump``).  Only a loop in fault counts
    (``cell``: an uncommissioned loop's alarms are withheld)."""
    from monitor.detection.machine import Alarm, decide

    by: dict[tuple[str, str], Rows] = defaultdict(list)
    for r in rows:
        if r.get("loop"):
            by[(r["machine"], r["log"])].append(r)
    for same in by.values():
        alarms = [
            Alarm(
                r["loop"],
                float(r["first_alarm_t"]),
                float("nan") if r.get("max_level") is None else float(r["max_level"]),
                r.get("alarm_since_t"),
            )
            for r in same
            if cell(r) == "fault" and r.get("first_alarm_t") is not None
        ]
        found = decide(alarms)
        roles: dict[str, str] = {}
        if found.named is not None:
            roles = {s: "secondary" for s in found.secondary}
            roles |= {e: "explained_by_pump" for e in found.explained}
            roles[found.named] = "named"
        for r in same:
            r["finding"] = found.named
            r["finding_role"] = roles.get(r["loop"])
