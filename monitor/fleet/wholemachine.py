"""What `monitor fleet run` does not judge yet: each loop of a whole machine's logs.

A fleet row is one log judged as one loop (`monitor detect LOG` without ``--loop``).  A
whole-machine log (every loop's signals of dbc/excavator4.dbc, as `monitor simulate-fleet
--machine excavator4` writes) read that way is its boom loop alone, judged with a
single-loop model: a stick, bucket or swing fault would never show and the machine would
read healthy.  Rather than such a verdict, the run is refused before any work, with one
line: a config of several loops (``loops:``), or a log that carries another loop's signals
(a CSV column, or a frame of another loop's message, among its first lines).
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

from monitor.errors import ConfigError
from monitor.fleet.layout import Fleet
from monitor.resources import resource_path

#: Bytes read from the start of each log: a whole machine sends every loop's frames every
#: 10 ms, so a few hundred candump lines hold each of them.
SNIFF_BYTES = 32768
_DETECT_HINT = (
    "judge a loop of a log with `monitor detect LOG --config config/excavator4.yaml "
    "--loop NAME` (commissioned with `monitor train ... --loop NAME`)"
)


@lru_cache(maxsize=1)
def other_loops() -> tuple[dict[str, str], dict[int, str]]:
    """The shipped whole machine's (config/excavator4.yaml) loops after the first: each
    loop's DBC signal name -> loop, and each frame id carrying one of them -> loop."""
    import cantools

    from monitor.config.settings import load_config

    cfg = load_config(resource_path("config", "excavator4.yaml"))
    names: dict[str, str] = {}
    for lc in cfg.monitored_loops[1:]:
        for signal in lc.signals.values():
            if signal is not None:
                names[signal] = lc.name
    db = cantools.database.load_file(str(cfg.dbc))
    ids = {
        int(msg.frame_id): names[s.name]
        for msg in db.messages
        for s in msg.signals
        if s.name in names
    }
    return names, ids


def loops_in(path: Path) -> list[str]:
    """The other loops (stick, bucket, swing) whose signals the start of log ``path``
    carries; [] for a one-loop log (or one that cannot be read: its row will say why)."""
    names, ids = other_loops()
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


def refuse_whole_machines(fleet: Fleet, loops_in_config: list[str]) -> None:
    """Raise a ``ConfigError`` (one line) when the run would judge whole machines as one
    loop: a config of several ``loops`` (``loops_in_config``), or a log of several loops."""
    if len(loops_in_config) > 1:
        raise ConfigError(
            f"--config declares {len(loops_in_config)} loops ({', '.join(loops_in_config)}): "
            "`monitor fleet run` judges one loop per log and does not yet judge each loop of "
            f"a whole machine; {_DETECT_HINT}"
        )
    for m in fleet.machines:
        for p in (*m.commissioning, *m.logs):
            found = loops_in(p)
            if found:
                raise ConfigError(
                    f"{fleet.relative(p)}: a whole-machine log (it carries the "
                    f"{', '.join(found)} loops' signals of dbc/excavator4.dbc): `monitor "
                    "fleet run` judges one loop per log and does not yet judge each loop "
                    f"with its machine's per-loop commissioning; {_DETECT_HINT}"
                )
