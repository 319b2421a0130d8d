"""One loop of a whole-machine recording for the gap tool (`monitor gap --loop NAME`).

The recording (candump log or CSV whose columns are the DBC's signal names) is read through
a monitor config's ``dbc`` and ``loops:`` (default: the shipped config/excavator4.yaml), the
loop's signals under the contract names (``monitor.offline.recordings.loop_recording``).

The gap tool drives the single-loop simulator: one cylinder on a pressure-compensated pump
of its own.  Where that cannot stand for the loop the diagnosis is refused before the
recording is read, with one line saying why, rather than a gap that would be the pump's or
the house's and not the loop's:

- the swing: a motor turning the house's inertia, not a cylinder under a load;
- any loop of a config whose loops share a load-sensing pump (``plausibility.pump_system:
  load_sensing``): PP sits the margin above the highest load of the open sections and the
  neighbours take flow from the same pump, where the simulator's pump holds its compensator
  setting for this loop alone.
"""

from __future__ import annotations

from pathlib import Path

from monitor.config.loops import LoopConfig
from monitor.config.settings import MonitorConfig, load_config
from monitor.errors import ConfigError, MonitorError
from monitor.io.recording import Recording
from monitor.resources import resource_path
from monitor.signals import is_neighbour

#: The contract's loop that is the swing motor (docs/reference/contracts.md, Names).
MOTOR_LOOPS = ("swing",)


class LoopNotSimulatedError(MonitorError, ValueError):
    """The single-loop simulator cannot stand for this loop of the machine: not diagnosed."""

    exit_code = 3


def loop_config(path: Path | None) -> MonitorConfig:
    """The monitor config naming the recording's loops (default: the shipped whole
    machine's, config/excavator4.yaml)."""
    return load_config(path if path is not None else resource_path("config", "excavator4.yaml"))


def gap_loop(cfg: MonitorConfig, name: str) -> LoopConfig:
    """Loop ``name`` of ``cfg`` if the single-loop simulator can stand for it; raises a
    ``ConfigError`` (exit 2) for a loop the config does not have, a
    ``LoopNotSimulatedError`` (exit 3) for one it cannot stand for."""
    loops = cfg.monitored_loops
    known = [lc.name for lc in loops]
    if name not in known:
        raise ConfigError(
            f"--loop {name!r}: no such loop in {cfg.source}; loops: {', '.join(known)}"
        )
    if name in MOTOR_LOOPS:
        raise LoopNotSimulatedError(
            f"--loop {name}: the swing is a motor turning the house's inertia; the gap tool's "
            "single-loop simulator is a cylinder under a load, so it cannot stand for it "
            "(not diagnosed)"
        )
    if cfg.gating.plausibility.pump.load_sensing and len(loops) > 1:
        others = ", ".join(n for n in known if n != name)
        raise LoopNotSimulatedError(
            f"--loop {name}: in {cfg.source} the {name} shares a load-sensing pump with "
            f"{others} (plausibility.pump_system), whose flow it shares and whose loads set PP; "
            "the gap tool's single-loop simulator feeds one loop from a pressure-compensated "
            "pump of its own, so the gap would be the pump's, not the loop's (not diagnosed)"
        )
    return next(lc for lc in loops if lc.name == name)


def read_gap_loop(path: Path, cfg: MonitorConfig, name: str) -> Recording:
    """Loop ``name``'s signals of the whole-machine recording ``path`` under the contract
    names (PP, PA, PB, QP, SpoolCmd, PumpDispCmd, EngineSpeed, OilTemp, RodPos when the loop
    has it), checked by :func:`gap_loop` first."""
    from monitor.offline.recordings import read_loop

    gap_loop(cfg, name)
    rec = read_loop(path, cfg, name)
    # The other loops' commands (SpoolCmd@LOOP) are the detector's inputs, not the gap's.
    columns = {k: v for k, v in rec.columns.items() if not is_neighbour(k)}
    return Recording(t=rec.t, columns=columns, source=rec.source, meta=rec.meta)
