"""The ``loops:`` section: several hydraulic loops (boom, stick, bucket, swing) in one daemon.

Each loop has its own model, its own sensor signals on the bus and its own MON_Alarm frame
and J1939 address; all share the bus, the clock and the signals a loop does not rename
(EngineSpeed and OilTemp, typically).  ``signals`` maps a contract name
(docs/reference/contracts.md: PP, PA, PB, QP, SpoolCmd, PumpDispCmd, EngineSpeed, OilTemp,
RodPos) to the DBC signal that carries it for this loop; a contract name not listed is read
from the DBC signal of the same name,
and ``RodPos: null`` says the loop has no rod position (a swing motor).

Without a ``loops`` section the daemon monitors one loop, ``boom``: the top-level ``model``,
the contract names, MON_Alarm and ``j1939.source_address`` (the behaviour before loops).
Checks against the DBC (do the signals and messages exist) happen where the DBC is loaded
(``monitor.config.layout``); here only the section's own shape is checked.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from monitor.errors import ConfigError
from monitor.sampling.sampler import ROW_COLUMNS
from monitor.schema.sections import key_text, shown
from monitor.signals import ROD_POS
from monitor.sim.machine import MachineParams, load_machine

DEFAULT_LOOP = "boom"
ALARM_MESSAGE = "MON_Alarm"
_NAME = re.compile(r"^[a-z][a-z0-9_]{0,31}$")  # goes into file names and event lines
_KEYS = ("name", "model", "signals", "alarm_message", "source_address", "machine")


@dataclass(frozen=True)
class LoopConfig:
    name: str
    model: Path
    signals: dict[str, str | None] = field(default_factory=dict)  # contract -> DBC signal
    alarm_message: str = ALARM_MESSAGE  # this loop's MON_Alarm-layout message in the DBC
    source_address: int = 0xA0  # J1939 address of this loop's DM1/DM2 (one per loop)
    #: The loop's machine (its ``machine:`` simulator YAML, None: not named), checked against
    #: the one its model was trained on.
    machine: MachineParams | None = None
    machine_source: Path | None = None

    def dbc_signal(self, contract: str) -> str | None:
        """The DBC signal carrying ``contract`` for this loop (None: the loop has none)."""
        return self.signals.get(contract, contract)


def default_loops(
    model: Path,
    source_address: int,
    machine: MachineParams | None = None,
    machine_source: Path | None = None,
) -> tuple[LoopConfig, ...]:
    """The single loop of a config without ``loops`` (``machine``: the top-level key's)."""
    return (
        LoopConfig(
            DEFAULT_LOOP,
            model,
            source_address=source_address,
            machine=machine,
            machine_source=machine_source,
        ),
    )


def parse_loops(
    raw: Any, source: Path, path_of: Callable[[Any, str], Path], first_address: int
) -> tuple[LoopConfig, ...]:
    """The ``loops`` list; ``path_of(value, key)`` resolves and checks a model path, and
    loop i's default J1939 address is ``first_address + i``."""
    if not isinstance(raw, list) or not raw:
        raise ConfigError(f"{source}: loops must be a non-empty list of loops")
    loops = [_loop(item, i, source, path_of, first_address + i) for i, item in enumerate(raw)]
    for key in ("name", "alarm_message", "source_address"):
        seen: dict[Any, int] = {}
        for i, lp in enumerate(loops):
            value = getattr(lp, key)
            if value in seen:
                raise ConfigError(
                    f"{source}: loops[{i}].{key} {shown(value)} is also loops"
                    f"[{seen[value]}]'s; each loop needs its own"
                )
            seen[value] = i
    return tuple(loops)


def _loop(
    item: Any, i: int, source: Path, path_of: Callable[[Any, str], Path], address: int
) -> LoopConfig:
    where = f"loops[{i}]"
    _check_keys(item, source, where)
    name = item["name"]
    if not isinstance(name, str) or not _NAME.match(name):
        raise ConfigError(
            f"{source}: {where}.name must be lower case letters, digits and _ "
            f"(starting with a letter, at most 32), got {shown(name)}"
        )
    signals = _signals(item.get("signals") or {}, source, where)
    alarm = item.get("alarm_message", ALARM_MESSAGE)
    if not isinstance(alarm, str) or not alarm:
        raise ConfigError(
            f"{source}: {where}.alarm_message must be a DBC message name, got {shown(alarm)}"
        )
    sa = item.get("source_address", address)
    if isinstance(sa, bool) or not isinstance(sa, int) or not 0 <= sa <= 253:
        raise ConfigError(
            f"{source}: {where}.source_address must be a whole number 0..253, got {shown(sa)}"
        )
    machine = None if item.get("machine") is None else path_of(item["machine"], f"{where}.machine")
    return LoopConfig(
        name,
        path_of(item["model"], f"{where}.model"),
        signals,
        alarm,
        sa,
        None if machine is None else load_machine(machine),
        machine,
    )


def _check_keys(item: Any, source: Path, where: str) -> None:
    """A mapping of known keys with at least a name and a model."""
    if not isinstance(item, dict):
        raise ConfigError(f"{source}: {where} must be a mapping with name and model")
    unknown = set(item) - set(_KEYS)
    if unknown:
        raise ConfigError(
            f"{source}: unknown key {where}.{sorted(map(key_text, unknown))[0]}; "
            f"known: {', '.join(_KEYS)}"
        )
    for key in ("name", "model"):
        if key not in item:
            raise ConfigError(f"{source}: {where} misses key {key!r}")


def _signals(signals: Any, source: Path, where: str) -> dict[str, str | None]:
    """A loop's ``signals`` mapping checked: contract names to distinct DBC signal names
    (``RodPos: null``: the loop has no rod position)."""
    if not isinstance(signals, dict):
        raise ConfigError(
            f"{source}: {where}.signals must be a mapping of contract names to DBC signal names"
        )
    for contract, dbc_name in signals.items():
        if contract not in ROW_COLUMNS:
            raise ConfigError(
                f"{source}: {where}.signals: unknown signal {shown(contract)}; "
                f"known: {', '.join(ROW_COLUMNS)}"
            )
        if dbc_name is None and contract == ROD_POS.name:
            continue  # optional: this loop has no rod position
        if not isinstance(dbc_name, str) or not dbc_name:
            raise ConfigError(
                f"{source}: {where}.signals.{contract} must be a DBC signal "
                f"name, got {shown(dbc_name)}"
            )
    targets = [signals.get(c, c) for c in ROW_COLUMNS]
    doubled = sorted({t for t in targets if t is not None and targets.count(t) > 1})
    if doubled:
        raise ConfigError(
            f"{source}: {where}.signals: DBC signal {shown(doubled[0])} would carry "
            "two of the loop's signals"
        )
    return dict(signals)
