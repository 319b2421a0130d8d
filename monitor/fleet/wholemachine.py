"""Which loops `monitor fleet run` judges each log as, checked before any work.

A fleet row is one log judged as one loop (`monitor detect LOG`), or, with a config of
several loops (``loops:``, as config/excavator4.yaml), one row per loop of each log
(`monitor detect LOG --loop NAME`), each loop commissioned on its own (`monitor train
--loop NAME`).  What would give a verdict the data cannot support is refused with one
line: a whole-machine log (every loop's signals of dbc/excavator4.dbc, as `monitor
simulate-fleet --machine excavator4` writes) read as its first loop alone with a one-loop
config (a stick, bucket or swing fault would never show and the machine would read
healthy); a one-loop log under a config of several loops (its other loops have no
signals); and ``--model`` with several loops (each loop's default model is its entry's).
"""

from __future__ import annotations

from monitor.errors import ConfigError
from monitor.fleet.layout import Fleet
from monitor.offline.loopsniff import loops_in

_CONFIG_HINT = (
    "judge each loop with a config of the machine's loops (`--config "
    "config/excavator4.yaml`: a row per loop, each loop commissioned as `monitor train "
    "--loop NAME` does)"
)


def fleet_loops(
    fleet: Fleet,
    loops_in_config: list[str],
    config: str | None,
    default_model: str | None,
    pump: bool = False,
) -> tuple[str, ...]:
    """The loops each log is judged as: ``()`` (the log as one loop) for a one-loop config,
    every loop of a config of several, and ``pump`` last with ``pump`` (the config's
    ``pump:``: the shared pump judged by its rule, commissioned per machine).  A
    ``ConfigError`` (one line) for what cannot be judged so (module docstring)."""
    several = len(loops_in_config) > 1
    if several and default_model is not None:
        raise ConfigError(
            f"--model {default_model}: the config declares {len(loops_in_config)} loops "
            f"({', '.join(loops_in_config)}), each with its own default model (its "
            "`loops:` entry's `model`); leave out --model"
        )
    for m in fleet.machines:
        for p in (*m.commissioning, *m.logs):
            found = loops_in(p, config) if several else loops_in(p)
            if found and not several:
                raise ConfigError(
                    f"{fleet.relative(p)}: a whole-machine log (it carries the "
                    f"{', '.join(found)} loops' signals of dbc/excavator4.dbc), and the "
                    f"config declares one loop: {_CONFIG_HINT}"
                )
            if several and not found:
                raise ConfigError(
                    f"{fleet.relative(p)}: a log of one loop (none of the "
                    f"{', '.join(loops_in_config[1:])} loops' signals among its first "
                    f"lines), and the config declares {len(loops_in_config)} loops "
                    f"({', '.join(loops_in_config)}): judge a fleet of one-loop logs with "
                    "a config of one loop"
                )
    return (*loops_in_config, *(("pump",) if pump else ())) if several else ()
