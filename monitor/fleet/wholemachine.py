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

from monitor.errors import ConfigError
from monitor.fleet.layout import Fleet
from monitor.offline.loopsniff import loops_in

_DETECT_HINT = (
    "judge a loop of a log with `monitor detect LOG --config config/excavator4.yaml "
    "--loop NAME` (commissioned with `monitor train ... --loop NAME`)"
)


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
