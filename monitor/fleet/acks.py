"""Acknowledged and shelved alarms: RESULTS/alarm-acks.jsonl, beside the Parquet tables.

One JSON line per operator action, appended and fsynced (never rewritten, so the file is
also the audit trail of who did what when); an alarm's newest line is its status.  The
Parquet tables of `monitor fleet run` are never touched: a rerun may rewrite them, and
the acknowledgements stay, keyed by log, kind and start of the episode.
"""

from __future__ import annotations

import datetime as dt
import json
import os
from dataclasses import dataclass
from pathlib import Path

from monitor.errors import ConfigError

ACK_FILE = "alarm-acks.jsonl"
ACTIONS = ("acknowledge", "shelve", "unshelve")
#: Shelving lasts this long unless said otherwise (ISA-18.2: shelving is time-limited).
SHELVE_DAYS = 7


@dataclass(frozen=True)
class AckStatus:
    action: str  # acknowledge, shelve or unshelve
    by: str
    at: str  # ISO 8601, UTC
    until: str | None  # shelved until (ISO 8601), for shelve
    note: str

    def shelved(self, now: dt.datetime) -> bool:
        return (
            self.action == "shelve"
            and self.until is not None
            and dt.datetime.fromisoformat(self.until) > now
        )

    @property
    def text(self) -> str:
        verb = {"acknowledge": "acknowledged", "shelve": "shelved", "unshelve": "unshelved"}
        until = f" until {self.until[:16].replace('T', ' ')}" if self.until else ""
        note = f": {self.note}" if self.note else ""
        return f"{verb[self.action]} by {self.by} at {self.at[:16].replace('T', ' ')}{until}{note}"


def ack_path(results: Path) -> Path:
    return results / ACK_FILE


def read_acks(results: Path) -> dict[str, AckStatus]:
    """Each alarm's newest status (an unreadable line is skipped: only a torn last line of
    a crash can be one)."""
    path = ack_path(results)
    out: dict[str, AckStatus] = {}
    if not path.is_file():
        return out
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            d = json.loads(line)
            out[d["alarm"]] = AckStatus(
                d["action"], d["by"], d["at"], d.get("until"), d.get("note", "")
            )
        except (ValueError, KeyError, TypeError):
            continue
    return out


def record(
    results: Path,
    alarm: str,
    action: str,
    by: str,
    note: str = "",
    shelve_days: float = SHELVE_DAYS,
    now: dt.datetime | None = None,
) -> AckStatus:
    """Append one operator action; its status.  ``by`` is required: an acknowledgement
    says who."""
    by, note = by.strip(), note.strip()
    if action not in ACTIONS:
        raise ConfigError(f"action {action!r}: one of {', '.join(ACTIONS)}")
    if not by:
        raise ConfigError("who acknowledges: a name is required")
    if not alarm:
        raise ConfigError("no alarm given")
    now = now or dt.datetime.now(dt.timezone.utc)
    until = (
        (now + dt.timedelta(days=shelve_days)).isoformat(timespec="seconds")
        if action == "shelve"
        else None
    )
    at = now.isoformat(timespec="seconds")
    line = {"alarm": alarm, "action": action, "by": by, "at": at, "until": until, "note": note}
    path = ack_path(results)
    with path.open("a", encoding="utf-8") as fh:
        fh.write(json.dumps(line) + "\n")
        fh.flush()
        os.fsync(fh.fileno())
    return AckStatus(action, by, at, until, note)
