"""The alarm episodes of a recording, named from the isolation votes over each of them.

``monitor detect`` feeds every decision of the shared per-sample path
(``monitor.detection.decision``) in time order to one ``EpisodeLog``; it counts the episodes,
keeps the first alarm's time and names each episode once, from the votes of all its fault
samples (the label held longest; it firms up as evidence accumulates, and may waver on the
way).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from monitor.detection.alarm import State
from monitor.detection.decision import Decision


@dataclass
class Alarms:
    """What the alarm machine made of a recording, per sample and per episode."""

    states: np.ndarray  # State per sample
    events: list[dict[str, Any]]
    first_alarm_t: float | None
    first_fault: str | None  # the label held longest over the first alarm episode
    episodes: int
    # Every alarm episode: start_t and end_t (s from the first sample; end_t None while
    # open at the end of the log), fault (named once, from the votes of the whole episode,
    # as ``first_fault``) and votes (fault samples per isolation label).
    named: list[dict[str, Any]] = field(default_factory=list)
    #: When each alarm episode a reference model would have raised was withheld instead
    #: (s from the first sample; ``Decision.withheld``).
    withheld_t: list[float] = field(default_factory=list)


class EpisodeLog:
    """Counts and names the alarm episodes as the decisions come, in time order."""

    def __init__(self) -> None:
        self.count = 0
        self.first_alarm_t: float | None = None
        self.named: list[dict[str, Any]] = []
        self._first_votes: dict[str, int] = {}  # over the first episode, short gaps included
        self._in_first = False
        self._votes: dict[str, int] = {}  # over the current episode
        self.withheld_t: list[float] = []

    def add(self, d: Decision, t_s: float, fault: str) -> None:
        """One decision at ``t_s`` (s from the first sample); ``fault`` the isolation then."""
        self.count += d.raised
        if d.withheld:
            self.withheld_t.append(t_s)
        if d.raised and self.first_alarm_t is None:
            self.first_alarm_t = t_s
            self._in_first = True
        if d.raised:
            self._votes = {}
            self.named.append({"start_t": t_s, "end_t": None, "votes": self._votes})
        if d.state is State.FAULT and self.named:
            self._votes[fault] = self._votes.get(fault, 0) + 1
        if self.named and self.named[-1]["end_t"] is None and not d.episode_open:
            self.named[-1]["end_t"] = t_s
        if self._in_first:
            if d.state is State.FAULT:
                self._first_votes[fault] = self._first_votes.get(fault, 0) + 1
            self._in_first = d.episode_open

    def result(self, states: np.ndarray, events: list[dict[str, Any]]) -> Alarms:
        """The episodes named, with the per-sample ``states`` and the ``events``."""
        for ep in self.named:
            ep["fault"] = vote_name(ep["votes"])
        first = vote_name(self._first_votes)
        return Alarms(
            states, events, self.first_alarm_t, first, self.count, self.named, self.withheld_t
        )


def vote_name(votes: dict[str, int]) -> str | None:
    """The fault an episode's isolation votes name: the label held for the most samples,
    a known fault before ``unknown`` (None: no votes)."""
    known = {k: v for k, v in votes.items() if k != "unknown"}
    pool = known or votes
    return max(pool, key=pool.__getitem__) if pool else None
