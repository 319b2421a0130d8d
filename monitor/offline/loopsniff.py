"""Which loops a log carries beyond the first, from its first lines: a whole machine's
recording (every loop's signals of dbc/excavator4.dbc) told from a one-loop one before it
is read as one loop.  A CSV's header names the other loops' columns (``Stick_PA``, ...); a
candump log's first lines carry frames of the other loops' messages.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

from monitor.resources import resource_path

#: Bytes read from the start of each log: a whole machine sends every loop's frames every
#: 10 ms, so a few hundred candump lines hold each of them.
SNIFF_BYTES = 32768


@lru_cache(maxsize=4)
def other_loops(config: str | None = None) -> tuple[dict[str, str], dict[int, str]]:
    """A whole machine's loops after the first (``config``'s, default the shipped
    config/excavator4.yaml): each loop's DBC signal name -> loop, and each frame id
    carrying one of them -> loop."""
    from monitor.codec.dbc import load_dbc
    from monitor.config.settings import load_config

    cfg = load_config(Path(config) if config else resource_path("config", "excavator4.yaml"))
    names: dict[str, str] = {}
    for lc in cfg.monitored_loops[1:]:
        for signal in lc.signals.values():
            if signal is not None:
                names[signal] = lc.name
    db = load_dbc(cfg.dbc)
    ids = {
        int(msg.frame_id): names[s.name]
        for msg in db.messages
        for s in msg.signals
        if s.name in names
    }
    return names, ids


def loops_in(path: Path, config: str | None = None) -> list[str]:
    """The other loops (stick, bucket, swing; ``config``'s after its first) whose signals
    the start of log ``path`` carries; [] for a one-loop log (or one that cannot be read:
    reading it will say why)."""
    names, ids = other_loops(config)
    try:
        with path.open("rb") as fh:
            head = fh.read(SNIFF_BYTES).decode("ascii", errors="replace")
    except OSError:
        return []
    found: set[str] = set()
    if path.suffix.lower() == ".csv":
        header = head.splitlines()[0] if head else ""
        found = {names[c.strip()] for c in header.split(",") if c.strip() in names}
    else:
        for line in head.splitlines():
            parts = line.split()
            if len(parts) >= 3 and "#" in parts[2]:
                try:
                    found.add(ids[int(parts[2].split("#", 1)[0], 16)])
                except (KeyError, ValueError):
                    continue
    return sorted(found, key=list(dict.fromkeys(names.values())).index)
