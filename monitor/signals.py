"""The signal contract: names, units and the CSV columns other tools rely on.

The user's page of it is docs/reference/contracts.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Signal:
    name: str
    unit: str
    description: str


#: Signals every contract CSV and the DBC carry, in the sampler's row order (after ``t``).
SIGNALS: tuple[Signal, ...] = (
    Signal("SpoolCmd", "%", "boom spool command, -100..100, positive extends (P->A, B->T)"),
    Signal("PumpDispCmd", "%", "pump displacement command, 0..100"),
    Signal("EngineSpeed", "rpm", "engine (pump shaft) speed"),
    Signal("OilTemp", "degC", "hydraulic oil temperature (1 Hz)"),
    Signal("PP", "bar", "pump outlet pressure, gauge"),
    Signal("PA", "bar", "valve port A (cap side) pressure, gauge"),
    Signal("PB", "bar", "valve port B (rod side) pressure, gauge"),
    Signal("QP", "L/min", "pump outlet flow"),
)

#: Optional signal: cylinder stroke from fully retracted.
ROD_POS = Signal("RodPos", "mm", "cylinder stroke from fully retracted (optional)")

#: Derived signal: the rod's speed (mm/s, either direction) over the last ``ROD_SPEED_SPAN``
#: samples of RodPos (``rod_speed_mm_s``).  No bus or CSV carries it: a model that names it
#: (``monitor train --rod-speed``) reads it from RodPos, the same arithmetic offline and per
#: tick.  A piston leak slows the rod for the same section flow, which the pressures and the
#: flow alone hardly show; as a magnitude, a slower rod is a shortfall either way.
ROD_SPEED = Signal("RodSpeed", "mm/s", "rod speed either way, from RodPos over 0.1 s")
#: Samples the rod speed spans (0.1 s): RodPos is read to about 0.5 mm, so a one-sample
#: difference scatters by some 70 mm/s at rest; over ten samples by some 7 mm/s.
ROD_SPEED_SPAN = 10
#: Each derived signal and the measured one it is computed from.
DERIVED: dict[str, str] = {ROD_SPEED.name: ROD_POS.name}

COMMAND_NAMES: tuple[str, ...] = ("SpoolCmd", "PumpDispCmd", "EngineSpeed", "OilTemp")
MEASURED_NAMES: tuple[str, ...] = ("PP", "PA", "PB", "QP")
SIGNAL_NAMES: tuple[str, ...] = tuple(s.name for s in SIGNALS)
#: Required CSV header columns (order free in files).
CSV_COLUMNS: tuple[str, ...] = ("t", *SIGNAL_NAMES)
UNITS: dict[str, str] = {s.name: s.unit for s in (*SIGNALS, ROD_POS, ROD_SPEED)} | {"t": "s"}

SAMPLE_PERIOD_S = 0.01
SAMPLE_RATE_HZ = 100.0

FAULT_NAMES: tuple[str, ...] = ("piston_wear", "spool_stroke", "spool_wear")
EFFECT_NAMES: tuple[str, ...] = (
    "entrained_air",
    "oil_viscosity",
    "cylinder_friction",
    "spool_dynamics",
    "valve_deadband",
    "pump_control_dynamics",
    "hose_compliance",
    "sensor_lag",
    "load_variation",
    "sensor_calibration",
)


def neighbour(contract: str, loop: str) -> str:
    """The name of another loop's signal as a loop's model reads it: ``SpoolCmd@stick``
    (the stick's spool command, an input of a section on the pump the stick shares)."""
    return f"{contract}@{loop}"


def is_neighbour(name: str) -> bool:
    """Whether ``name`` is another loop's signal (``neighbour``)."""
    return "@" in name


def contract_name(name: str) -> str:
    """The contract signal behind a model variable: ``SpoolCmd@stick`` -> ``SpoolCmd``."""
    return name.split("@", 1)[0]


def rod_speed_mm_s(now_mm: Any, then_mm: Any) -> Any:
    """The rod speed (mm/s, either direction) from RodPos now and ``ROD_SPEED_SPAN``
    samples before: floats per tick, arrays offline, the same arithmetic (NaN in, NaN out)."""
    return abs(now_mm - then_mm) / (ROD_SPEED_SPAN * SAMPLE_PERIOD_S)


def source_signal(name: str) -> str:
    """The measured column behind a model variable: RodPos for RodPos's derived RodSpeed
    (what goes stale when it is missing), the variable's own name otherwise."""
    return DERIVED.get(name, name)
