"""``pump:`` of a monitor config with several loops on one load-sensing pump: the pump
model file (``monitor train --pump``), and where the pump rule reads its signals in the
daemon's row (``monitor.detection.pump``).

    pump:
      model: pump_excavator4.pump.json
      alarm_message: MON_Alarm_Pump   # the default
      source_address: 164             # the default (0xA4): the pump's DM1 with J1939 on
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from monitor.detection.pump import PumpColumns
from monitor.errors import ConfigError
from monitor.model.pumplaw import PumpModel, load_pump_model
from monitor.schema.sections import shown

if TYPE_CHECKING:
    from monitor.config.settings import MonitorConfig

#: The contract signals of a section the pump rule reads.
SECTION_SIGNALS = ("SpoolCmd", "PA", "PB", "QP")
PUMP_ALARM = "MON_Alarm_Pump"
PUMP_SOURCE_ADDRESS = 0xA4
_KEYS = {"model", "alarm_message", "source_address"}
#: The pump alarm message's signals (``monitor.live.machine``).
PUMP_ALARM_SIGNALS = ("State", "Fault", "MarginResidual", "Threshold", "AlarmCount")


@dataclass(frozen=True)
class PumpSection:
    """``pump:``: the pump model file and the message its alarm goes out in."""

    model: Path
    alarm_message: str = PUMP_ALARM
    #: The pump's J1939 address (its DM1 with ``j1939.enabled``), MON_Alarm_Pump's 0xA4.
    source_address: int = PUMP_SOURCE_ADDRESS


def parse_pump(value: Any, source: Path, path: Callable[[Any, str], Path]) -> PumpSection | None:
    """``pump``: None, or a mapping with ``model`` (an existing file) and optionally
    ``alarm_message`` and ``source_address``."""
    if value is None:
        return None
    if not isinstance(value, dict) or "model" not in value or set(value) - _KEYS:
        raise ConfigError(
            f"{source}: pump must be a mapping with model (and optionally alarm_message, "
            f"source_address), got {shown(value)}"
        )
    address = value.get("source_address", PUMP_SOURCE_ADDRESS)
    if isinstance(address, bool) or not isinstance(address, int) or not 0 <= address <= 253:
        raise ConfigError(
            f"{source}: pump.source_address must be 0..253 (254 null, 255 global), "
            f"got {shown(address)}"
        )
    message = value.get("alarm_message", PUMP_ALARM)
    if not isinstance(message, str) or not message:
        raise ConfigError(
            f"{source}: pump.alarm_message must be a message name, got {shown(message)}"
        )
    return PumpSection(path(value["model"], "pump.model"), message, address)


def pump_columns(cfg: MonitorConfig, columns: Sequence[str]) -> PumpColumns:
    """The pump rule's signals in a row of ``columns``: the first loop's PP (one pump: every
    loop's PP is its outlet) and every loop's spool command, ports and flow."""
    loops = cfg.monitored_loops
    sections = []
    for lc in loops:
        names = {c: lc.dbc_signal(c) for c in SECTION_SIGNALS}
        missing = [c for c, n in names.items() if n is None or n not in columns]
        if missing:
            raise ConfigError(
                f"{cfg.source}: the pump rule needs loop {lc.name}'s {', '.join(missing)}"
            )
        sections.append({c: str(n) for c, n in names.items()})
    pp = loops[0].dbc_signal("PP")
    if pp is None or pp not in columns:
        raise ConfigError(f"{cfg.source}: the pump rule needs loop {loops[0].name}'s PP")
    return PumpColumns.of(columns, pp, sections, [lc.name for lc in loops])


def load_pump(cfg: MonitorConfig) -> PumpModel | None:
    """The config's pump model (None without ``pump:``), its margin checked against the
    config's ``plausibility.ls_margin_bar``."""
    if cfg.pump is None:
        return None
    pump = cfg.gating.plausibility.pump
    if not pump.load_sensing:
        raise ConfigError(
            f"{cfg.source}: pump.model needs plausibility.pump_system: load_sensing (the "
            "margin law is a load-sensing pump's)"
        )
    model = load_pump_model(cfg.pump.model)
    margin = pump.ls_margin_bar
    if abs(model.counting.margin_bar - margin) > 1e-9:
        raise ConfigError(
            f"{cfg.source}: pump.model {cfg.pump.model} was trained with a margin of "
            f"{model.counting.margin_bar:g} bar, plausibility.ls_margin_bar is {margin:g}"
        )
    return model
