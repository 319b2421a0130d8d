"""The closing line of `monitor fleet run`: what the fleet's rows say, and its exit code."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

#: Failed logs named in the closing line (the rest are counted; every one is a row).
FIRST_REASONS = 2


def _short(text: str, limit: int = 120) -> str:
    line = " ".join(text.split())
    return line if len(line) <= limit else line[: limit - 3] + "..."


@dataclass(frozen=True)
class Outcome:
    """Counts over the rows of the logs the fleet folder holds now (rows of logs since
    removed from the folder are left out).  ``judged``: a verdict; ``not_judged``: read,
    but nothing the detector could judge (engine off, too short, ...); ``failed``: could
    not be read or judged at all (the row's ``error``)."""

    judged: int
    not_judged: int
    failed: int
    new: int
    skipped: int
    reasons: list[str] = field(default_factory=list)
    per_loop: bool = False  # whole machines: a row per loop of each log

    @classmethod
    def of(
        cls,
        rows: Iterable[dict[str, Any]],
        keys: set[tuple[str, str, str]],
        new: int,
        skipped: int,
        per_loop: bool = False,
    ) -> Outcome:
        from monitor.fleet.store import row_key

        judged = not_judged = 0
        failed: list[dict[str, Any]] = []
        for r in sorted(rows, key=lambda r: (r["log"], r.get("loop") or "")):
            if row_key(r) not in keys:
                continue
            if r["error"] is not None:
                failed.append(r)
            elif r["verdict"] == "not_judged":
                not_judged += 1
            else:
                judged += 1
        reasons = [
            f"{r['log']}{' (' + r['loop'] + ')' if r.get('loop') else ''}: {_short(r['error'])}"
            for r in failed[:FIRST_REASONS]
        ]
        return cls(judged, not_judged, len(failed), new, skipped, reasons, per_loop)

    @property
    def exit_code(self) -> int:
        """0 when every log was read (whatever its verdict), 3 when any failed."""
        return 3 if self.failed else 0

    def line(self) -> str:
        total = self.judged + self.not_judged + self.failed
        unit = "log loops" if self.per_loop else "logs"
        text = (
            f"fleet: {total} {unit}: {self.judged} judged, {self.not_judged} not judged, "
            f"{self.failed} failed"
        )
        if self.reasons:
            more = self.failed - len(self.reasons)
            text += " (" + "; ".join(self.reasons) + (f"; {more} more" if more else "") + ")"
        return text + f"; {self.new} new this run, {self.skipped} already in results"
