"""The reference machine's nominal parameters, SI inside, loaded from config/simulator.yaml.

The YAML carries units in its key names (bar, L, mm, cc/rev); ``MachineParams`` holds SI
values only (Pa, m^3, m, kg, N, s).  ``load_machine`` validates every key once, at the edge,
with the same strict reader and value checks as config/monitor.yaml (``monitor.schema``);
the table below only declares each key's SI field, unit factor and range.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from monitor.errors import ConfigError
from monitor.resources import resource_path
from monitor.schema.sections import key_text, shown, value
from monitor.schema.yamlfile import read_yaml

BAR = 1e5  # Pa
LPM = 1e-3 / 60.0  # m^3/s per L/min


@dataclass(frozen=True)
class Oil:
    density_kg_m3: float = 870.0
    bulk_modulus_pa: float = 1.5e9


@dataclass(frozen=True)
class Pump:
    """The pressure-compensated pump and the speed it is driven at."""

    pump_disp_m3_rev: float = 11e-6
    compensator_enabled: bool = True
    compensator_start_pa: float = 190 * BAR
    compensator_full_pa: float = 200 * BAR
    nominal_speed_rpm: float = 2200.0


@dataclass(frozen=True)
class Line:
    """The pump line and its main relief."""

    line_volume_m3: float = 0.5e-3
    relief_crack_pa: float = 210 * BAR
    relief_full_pa: float = 220 * BAR


@dataclass(frozen=True)
class Valve:
    """The directional valve's metering edges."""

    valve_rated_flow_m3_s: float = 20 * LPM
    valve_rated_dp_pa: float = 10 * BAR
    laminar_dp_pa: float = 0.3 * BAR
    tank_pa: float = 0.0
    #: Share of the stroke over which each metering edge opens through notches (0: a
    #: linear edge): the open area grows with the square of the opening there and
    #: linearly beyond, the two joined with one slope (``monitor.sim.laws.metering``).
    notch_share: float = 0.0
    #: Steady flow forces against a soft centring spring (1/Pa, 0: none): the spool sent to
    #: ``x`` settles at ``x / (1 + flow_force * (drop in + drop out))`` across the edges it
    #: opens (``monitor.sim.laws.flow_forced``; a direct-operated spool).  The rated flow
    #: stays the flow at the rated drop across each edge, flow forces included.
    flow_force: float = 0.0

    @property
    def valve_kv(self) -> float:
        """Orifice coefficient per metering edge at full stroke, m^3/s per sqrt(Pa)."""
        return self.valve_rated_flow_m3_s / math.sqrt(self.valve_rated_dp_pa)


@dataclass(frozen=True)
class Cylinder:
    bore_m: float = 0.063
    rod_m: float = 0.036
    stroke_m: float = 0.5
    dead_volume_a_m3: float = 0.3e-3
    dead_volume_b_m3: float = 0.3e-3

    @property
    def area_a_m2(self) -> float:
        return math.pi / 4 * self.bore_m**2

    @property
    def area_b_m2(self) -> float:
        return math.pi / 4 * (self.bore_m**2 - self.rod_m**2)


@dataclass(frozen=True)
class Load:
    """What the cylinder moves: the boom's mass, its gravity load and friction."""

    mass_kg: float = 400.0
    gravity_load_n: float = 6000.0
    viscous_friction_n_s_m: float = 2000.0
    reference_rod_pos_m: float = 0.25


@dataclass(frozen=True)
class Solver:
    step_s: float = 2e-4


#: The machine's parts, as the simulator YAML's sections (``nominal_speed_rpm`` with the pump).
PARTS = ("oil", "pump", "line", "valve", "cylinder", "load", "solver")


@dataclass(frozen=True)
class MachineParams:
    """Nominal lumped parameters of one boom loop, all SI, by part.

    A parameter's name (its field in its part, e.g. ``bulk_modulus_pa``) is unique across
    the parts: ``value`` and ``with_changes`` take it without the part, as the sim-to-real
    tool and the fleet simulator name what they vary."""

    oil: Oil = field(default_factory=Oil)
    pump: Pump = field(default_factory=Pump)
    line: Line = field(default_factory=Line)
    valve: Valve = field(default_factory=Valve)
    cylinder: Cylinder = field(default_factory=Cylinder)
    load: Load = field(default_factory=Load)
    solver: Solver = field(default_factory=Solver)

    @property
    def relief_gain_m3_s_pa(self) -> float:
        """Relief flow per Pa above cracking: the pump's full flow at nominal speed."""
        full_flow = self.pump.pump_disp_m3_rev * self.pump.nominal_speed_rpm / 60.0
        return full_flow / (self.line.relief_full_pa - self.line.relief_crack_pa)

    def value(self, name: str) -> Any:
        """The parameter ``name`` (a field of one of the parts)."""
        return getattr(getattr(self, PART_OF[name]), name)

    def with_changes(self, **changes: Any) -> MachineParams:
        """A copy with the named parameters changed (SI floats; ``compensator_enabled`` a
        bool), each named without its part."""
        by_part: dict[str, dict[str, Any]] = {}
        for name, v in changes.items():
            if name not in PART_OF:
                raise TypeError(f"MachineParams has no parameter {name!r}")
            by_part.setdefault(PART_OF[name], {})[name] = v
        return replace(
            self, **{part: replace(getattr(self, part), **c) for part, c in by_part.items()}
        )

    @classmethod
    def of(cls, values: Mapping[str, Any]) -> MachineParams:
        """The defaults with ``values`` (parameters named without their part)."""
        return cls().with_changes(**values)


#: Parameter name -> the part that holds it.
PART_OF: dict[str, str] = {
    f.name: part
    for part, kind in zip(PARTS, (Oil, Pump, Line, Valve, Cylinder, Load, Solver), strict=True)
    for f in fields(kind)
}


# YAML key -> (MachineParams parameter, factor to SI, lower bound, upper bound) in YAML units.
_KEYS: dict[str, dict[str, tuple[str, float, float, float]]] = {
    "oil": {
        "density_kg_m3": ("density_kg_m3", 1.0, 700, 1100),
        "bulk_modulus_gpa": ("bulk_modulus_pa", 1e9, 0.1, 3.0),
    },
    "pump": {
        "displacement_cc_rev": ("pump_disp_m3_rev", 1e-6, 0.5, 500),
        "compensator_start_bar": ("compensator_start_pa", BAR, 10, 500),
        "compensator_full_bar": ("compensator_full_pa", BAR, 10, 500),
    },
    "line": {
        "volume_l": ("line_volume_m3", 1e-3, 0.01, 50),
        "relief_crack_bar": ("relief_crack_pa", BAR, 10, 500),
        "relief_full_bar": ("relief_full_pa", BAR, 10, 600),
    },
    "valve": {
        "rated_flow_lpm": ("valve_rated_flow_m3_s", LPM, 0.1, 1000),
        "rated_dp_bar": ("valve_rated_dp_pa", BAR, 0.5, 100),
        "laminar_dp_bar": ("laminar_dp_pa", BAR, 0.01, 5),
        "tank_bar": ("tank_pa", BAR, 0, 20),
        "notch_share_pct": ("notch_share", 0.01, 0, 90),
        "flow_force_per_bar": ("flow_force", 1.0 / BAR, 0, 1),
    },
    "cylinder": {
        "bore_mm": ("bore_m", 1e-3, 10, 500),
        "rod_mm": ("rod_m", 1e-3, 5, 400),
        "stroke_mm": ("stroke_m", 1e-3, 10, 5000),
        "dead_volume_a_l": ("dead_volume_a_m3", 1e-3, 0.01, 50),
        "dead_volume_b_l": ("dead_volume_b_m3", 1e-3, 0.01, 50),
    },
    "load": {
        "mass_kg": ("mass_kg", 1.0, 1, 1e5),
        "gravity_load_n": ("gravity_load_n", 1.0, -1e6, 1e6),
        "viscous_friction_n_s_per_m": ("viscous_friction_n_s_m", 1.0, 0, 1e6),
        "reference_rod_pos_mm": ("reference_rod_pos_m", 1e-3, 0, 5000),
    },
    "solver": {"step_us": ("step_s", 1e-6, 5, 1000)},
}
_BOOL_KEYS = {("pump", "compensator_enabled"): "compensator_enabled"}


def machine_from_mapping(data: Any, source: str = "<config>") -> MachineParams:
    """Validate a parsed simulator YAML and convert it to ``MachineParams``."""
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: expected a mapping of sections, got {type(data).__name__}")
    values: dict[str, Any] = {}
    for section, content in data.items():
        if section not in _KEYS:
            raise ConfigError(
                f"{source}: unknown section {shown(section)}; known: {', '.join(_KEYS)}"
            )
        if not isinstance(content, dict):
            raise ConfigError(f"{source}: section {shown(section)} must be a mapping")
        for key, raw in content.items():
            if (section, key) in _BOOL_KEYS:
                values[_BOOL_KEYS[section, key]] = value("bool", raw, f"{section}.{key}", source)
                continue
            if key not in _KEYS[section]:
                known = ", ".join([*_KEYS[section], *(k for s, k in _BOOL_KEYS if s == section)])
                raise ConfigError(
                    f"{source}: unknown key {section}.{key_text(key)}; known: {known}"
                )
            name, factor, low, high = _KEYS[section][key]
            raw = value("float", raw, f"{section}.{key}", source)  # a finite number
            if not low <= raw <= high:
                raise ConfigError(f"{source}: {section}.{key} = {raw} is outside {low}..{high}")
            values[name] = float(raw) * factor
    params = MachineParams.of(values)
    _check_consistency(params, source)
    return params


def _check_consistency(p: MachineParams, source: str) -> None:
    if p.cylinder.rod_m >= p.cylinder.bore_m:
        raise ConfigError(f"{source}: cylinder.rod_mm must be smaller than cylinder.bore_mm")
    if p.pump.compensator_full_pa <= p.pump.compensator_start_pa:
        raise ConfigError(f"{source}: pump.compensator_full_bar must exceed compensator_start_bar")
    if p.line.relief_full_pa <= p.line.relief_crack_pa:
        raise ConfigError(f"{source}: line.relief_full_bar must exceed relief_crack_bar")


def load_machine(path: str | Path | None = None) -> MachineParams:
    """Load the simulator config (default: the shipped config/simulator.yaml)."""
    path = Path(path) if path is not None else resource_path("config", "simulator.yaml")
    return machine_from_mapping(read_yaml(path, "simulator config") or {}, str(path))
