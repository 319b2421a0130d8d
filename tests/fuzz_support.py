"""What the fuzz suite (tests/test_fuzz.py) tried: per target, how many inputs ended how.

Filled by ``outcome``; tests/conftest.py prints it in the terminal summary."""

from __future__ import annotations

from collections import Counter, defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

from monitor.errors import MonitorError

#: target -> outcome ("ok" or the MonitorError subclass) -> inputs
OUTCOMES: defaultdict[str, Counter[str]] = defaultdict(Counter)

#: Longest message allowed besides the file's path: errors cut what they show of an input.
MAX_MESSAGE = 300


def outcome(target: str, fn: Callable[[], Any], path: Path) -> tuple[str, Any]:
    """Run ``fn``: a result, or a MonitorError with a one-line message of bounded length.
    Any other exception propagates (the fuzz property fails).  Returns the outcome kind
    ("ok" or the error's class name) and the result or the message."""
    try:
        result = fn()
    except MonitorError as exc:
        msg = str(exc)
        assert msg, f"{type(exc).__name__} without a message"
        assert "\n" not in msg and "\r" not in msg, f"message of more than one line: {msg!r}"
        rest = msg.replace(str(path), "")
        assert len(rest) <= MAX_MESSAGE, f"message of {len(rest)} characters: {msg[:400]!r}"
        kind, result = type(exc).__name__, msg
    else:
        kind = "ok"
    OUTCOMES[target][kind] += 1
    return kind, result


def summary_lines() -> list[str]:
    """One line per target: inputs tried and their outcomes, most frequent first."""
    out = []
    for target in sorted(OUTCOMES):
        counts = OUTCOMES[target]
        kinds = ", ".join(f"{k} {n}" for k, n in counts.most_common())
        out.append(f"{target}: {sum(counts.values())} inputs ({kinds})")
    return out
