"""Alarm episodes of a log, and the fault a machine is named with.

A fault episode comes from the detector (``Detection.episodes``): its start, its end and the
isolation votes of every fault sample in it, and it is named once, by the label with the
most votes (a known fault before ``unknown``).  A sensor episode is a run of sensor-fault
events, named by the signal and check the plausibility found (or the stale signal).  Each
carries the DM1 trouble code (SPN, FMI) the daemon sends for it, from the J1939 settings.

A machine is named from all its fault episodes' votes added up (``machine_fault``): one
episode that isolation named otherwise does not rename the machine; the page shows each
episode's votes beside the machine's tally, so a change of name is a change of evidence
the reader can see.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

#: A sensor finding without a named signal (the DM1 "unknown" sensor SPN).
UNKNOWN = "unknown"


def fault_episodes(named: list[dict[str, Any]], end_s: float, j1939: Any) -> list[dict]:
    """Episodes of ``Detection.episodes`` as rows: kind ``fault``, start/end (an episode
    still open at the end of the log ends at ``end_s``, ``open`` true), name, votes, DTC."""
    out = []
    for ep in named:
        name = ep.get("fault") or UNKNOWN
        key = name if name in j1939.fault_spn else UNKNOWN
        end = ep["end_t"]
        out.append(
            {
                "kind": "fault",
                "start_t": ep["start_t"],
                "end_t": end_s if end is None else end,
                "open": end is None,
                "name": name,
                "check": None,
                "votes": dict(ep["votes"]),
                "spn": int(j1939.fault_spn[key]),
                "fmi": int(j1939.fault_fmi[key]),
            }
        )
    return out


def sensor_episodes(events: list[dict[str, Any]], end_s: float, j1939: Any) -> list[dict]:
    """Runs of ``sensor_fault`` state events as rows: the first signal a check or staleness
    named in the run (``unknown`` if none) and its check, with the DM1 code."""
    out: list[dict] = []
    cur: dict | None = None
    for e in events:
        if e.get("state") != "sensor_fault":
            if cur is not None:
                cur["end_t"], cur["open"] = float(e["t"]), False
                out.append(cur)
                cur = None
            continue
        if cur is None:
            cur = {
                "kind": "sensor_fault",
                "start_t": float(e["t"]),
                "end_t": end_s,
                "open": True,
                "name": UNKNOWN,
                "check": None,
                "votes": {},
            }
        if cur["name"] == UNKNOWN and e.get("sensor"):
            cur["name"], cur["check"] = e["sensor"], e.get("sensor_check")
    if cur is not None:
        out.append(cur)
    for ep in out:
        name, check = ep["name"], ep["check"]
        ep["spn"] = int(j1939.sensor_spn.get(name, j1939.sensor_spn[UNKNOWN]))
        fmi = j1939.check_fmi.get(check) if check not in (None, "stale") else None
        ep["fmi"] = int(j1939.sensor_fmi if fmi is None else fmi)
    return out


def log_episodes(named: list[dict], events: list[dict], end_s: float, j1939: Any) -> str:
    """Every episode of one log, in time order, as the JSON text of the ``episodes``
    column of logs.parquet."""
    eps = fault_episodes(named, end_s, j1939) + sensor_episodes(events, end_s, j1939)
    eps.sort(key=lambda e: e["start_t"])
    for ep in eps:
        ep["duration_s"] = round(ep["end_t"] - ep["start_t"], 3)
    return json.dumps(eps, sort_keys=True)


def row_episodes(row: dict[str, Any]) -> list[dict[str, Any]]:
    """The episodes of a logs.parquet row (none for results written before the column)."""
    text = row.get("episodes")
    return json.loads(text) if text else []


@dataclass(frozen=True)
class MachineFault:
    """The fault a machine is named with, from every fault episode's isolation votes."""

    name: str | None  # None: no fault episode
    votes: dict[str, int]  # fault samples per label, over every episode
    episodes: int  # fault episodes counted
    renamed: int  # episodes whose own name differs from the machine's

    @property
    def share(self) -> float | None:
        """The share of the named label among all votes."""
        total = sum(self.votes.values())
        return None if self.name is None or not total else self.votes.get(self.name, 0) / total

    @property
    def evidence(self) -> str:
        """e.g. ``isolation 82 % of 3,412 fault samples over 9 episodes (2 named otherwise)``"""
        if self.name is None or self.share is None:
            return ""
        other = f", {self.renamed} named otherwise" if self.renamed else ""
        n = sum(self.votes.values())
        return (
            f"isolation {self.share * 100:.0f} % of {n:,} fault samples over "
            f"{self.episodes} episode{'s' if self.episodes != 1 else ''}{other}"
        )


def machine_fault(rows: list[dict[str, Any]]) -> MachineFault:
    """The machine's fault from the votes of all its fault episodes (rows in time order);
    older rows without episodes count their ``fault`` as one vote."""
    votes: dict[str, int] = {}
    names: list[str] = []
    for r in rows:
        eps = [e for e in row_episodes(r) if e["kind"] == "fault"]
        if not eps and r.get("alarm") and r.get("fault") and r.get("episodes") is None:
            eps = [{"name": r["fault"], "votes": {r["fault"]: 1}}]
        for e in eps:
            names.append(e["name"])
            for k, v in e["votes"].items():
                votes[k] = votes.get(k, 0) + int(v)
    known = {k: v for k, v in votes.items() if k != UNKNOWN}
    pool = known or votes
    name = max(pool, key=pool.__getitem__) if pool else (names[0] if names else None)
    return MachineFault(name, votes, len(names), sum(n != name for n in names))
