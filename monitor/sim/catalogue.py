"""The effects' catalogue: every effect the nominal model leaves out, its physical
parameters (units, defaults, ranges) and named choices, for ``--help``, validation and the
sim-to-real tool.  ``monitor.sim.effects`` makes and parses the effects themselves.
"""

from __future__ import annotations

from dataclasses import dataclass

from monitor.errors import ConfigError
from monitor.signals import EFFECT_NAMES


@dataclass(frozen=True)
class ParamSpec:
    name: str
    unit: str
    default: float
    low: float
    high: float
    doc: str


@dataclass(frozen=True)
class ChoiceSpec:
    """A parameter that names something (e.g. which signal) instead of a number."""

    name: str
    options: tuple[str, ...]
    default: str
    doc: str


@dataclass(frozen=True)
class SensorCalSignal:
    """A measured signal ``sensor_calibration`` can act on: its unit, the unit as written in
    the gap report's key names (``QP_offset_lpm``) and the largest offset accepted."""

    unit: str
    key_unit: str
    max_offset: float


#: Signals a sensor calibration error can affect, in the contract's order and units.
SENSOR_CAL_SIGNALS: dict[str, SensorCalSignal] = {
    "PP": SensorCalSignal("bar", "bar", 20.0),
    "PA": SensorCalSignal("bar", "bar", 20.0),
    "PB": SensorCalSignal("bar", "bar", 20.0),
    "QP": SensorCalSignal("L/min", "lpm", 10.0),
    "RodPos": SensorCalSignal("mm", "mm", 50.0),
}


@dataclass(frozen=True)
class EffectSpec:
    name: str
    doc: str
    params: tuple[ParamSpec, ...]
    choices: tuple[ChoiceSpec, ...] = ()

    def param(self, name: str) -> ParamSpec:
        for p in self.params:
            if p.name == name:
                return p
        known = ", ".join(p.name for p in self.params)
        raise ConfigError(f"effect {self.name!r} has no parameter {name!r}; known: {known}")


CATALOGUE: dict[str, EffectSpec] = {
    spec.name: spec
    for spec in (
        EffectSpec(
            "entrained_air",
            "pressure-dependent effective bulk modulus of oil with entrained air "
            "(Simscape hydraulic-fluid formula): soft at low pressure",
            (
                ParamSpec(
                    "air_fraction",
                    "-",
                    0.01,
                    0.0005,
                    0.1,
                    "air volume per liquid volume at atmospheric pressure",
                ),
                ParamSpec(
                    "polytropic_index",
                    "-",
                    1.4,
                    1.0,
                    1.4,
                    "gas compression exponent (1 isothermal, 1.4 adiabatic)",
                ),
                ParamSpec(
                    "dissolved_at_bar",
                    "bar",
                    30.0,
                    2.0,
                    200.0,
                    "law dissolving: gauge pressure at which all the air has gone into solution",
                ),
            ),
            (
                ChoiceSpec(
                    "law",
                    ("free_air", "dissolving"),
                    "free_air",
                    "mixture law: free_air keeps the air as gas at every pressure (Simscape); "
                    "dissolving lets it go into solution linearly up to dissolved_at_bar",
                ),
            ),
        ),
        EffectSpec(
            "oil_viscosity",
            "leakage (pump, piston seal, valve clearances) and part of the cylinder friction "
            "follow oil viscosity, from OilTemp through the Walther equation (ASTM D341)",
            (
                ParamSpec("nu40_cst", "cSt", 46.0, 15.0, 150.0, "kinematic viscosity at 40 degC"),
                ParamSpec("nu100_cst", "cSt", 6.8, 3.0, 20.0, "kinematic viscosity at 100 degC"),
                ParamSpec(
                    "pump_leak_lpm_per_100bar",
                    "L/min",
                    1.0,
                    0.0,
                    5.0,
                    "pump internal leakage at 100 bar and 40 degC (laminar, ~p/nu)",
                ),
                ParamSpec(
                    "friction_share",
                    "-",
                    0.5,
                    0.0,
                    1.0,
                    "share of the viscous friction that scales with viscosity",
                ),
                ParamSpec(
                    "piston_leak_lpm_per_100bar",
                    "L/min",
                    0.0,
                    0.0,
                    5.0,
                    "leakage across the piston seal (A<->B) at 100 bar and 40 degC (laminar)",
                ),
                ParamSpec(
                    "valve_leak_lpm_per_100bar",
                    "L/min",
                    0.0,
                    0.0,
                    2.0,
                    "clearance leakage of each closed metering edge (P->A, P->B, A->T, B->T) "
                    "at 100 bar and 40 degC (laminar)",
                ),
            ),
        ),
        EffectSpec(
            "cylinder_friction",
            "Coulomb and Stribeck friction of the cylinder seals (on top of viscous)",
            (
                ParamSpec("coulomb_n", "N", 500.0, 0.0, 3000.0, "Coulomb (sliding) friction"),
                ParamSpec(
                    "static_n", "N", 800.0, 0.0, 5000.0, "breakaway friction, at least coulomb_n"
                ),
                ParamSpec(
                    "stribeck_velocity_mm_s",
                    "mm/s",
                    10.0,
                    1.0,
                    100.0,
                    "velocity over which static friction decays to Coulomb",
                ),
                ParamSpec(
                    "stribeck_exponent",
                    "-",
                    2.0,
                    0.5,
                    2.0,
                    "shape of that decay, exp(-|v/vs|^e): 2 Gaussian, 1 exponential",
                ),
                ParamSpec(
                    "smoothing_velocity_mm_s",
                    "mm/s",
                    0.5,
                    0.2,
                    20.0,
                    "friction sign is tanh(v/this): 0.5 is nearly sharp; a few mm/s "
                    "stand in for presliding (a smooth, LuGre-like reversal)",
                ),
            ),
        ),
        EffectSpec(
            "spool_dynamics",
            "second-order spool position response to SpoolCmd (mobile valves 5-20 Hz)",
            (
                ParamSpec("natural_freq_hz", "Hz", 10.0, 2.0, 40.0, "spool natural frequency"),
                ParamSpec("damping_ratio", "-", 0.7, 0.3, 1.5, "spool damping ratio"),
            ),
        ),
        EffectSpec(
            "valve_deadband",
            "spool overlap: no metering edge opens until the spool passes the overlap",
            (ParamSpec("overlap_pct", "% stroke", 10.0, 0.0, 30.0, "overlap of each land"),),
        ),
        EffectSpec(
            "pump_control_dynamics",
            "pump displacement (and so the compensator) follows its target with a lag: "
            "first order, or second order (a swashplate and its control piston that ring)",
            (
                ParamSpec("time_constant_ms", "ms", 80.0, 5.0, 500.0, "displacement time constant"),
                ParamSpec(
                    "natural_freq_hz",
                    "Hz",
                    5.0,
                    0.5,
                    50.0,
                    "law second_order: natural frequency of the displacement control",
                ),
                ParamSpec(
                    "damping_ratio",
                    "-",
                    0.7,
                    0.05,
                    2.0,
                    "law second_order: damping ratio of the displacement control",
                ),
            ),
            (
                ChoiceSpec(
                    "law",
                    ("first_order", "second_order"),
                    "first_order",
                    "first_order: a lag (time_constant_ms); second_order: a mass-spring-damper "
                    "response (natural_freq_hz, damping_ratio)",
                ),
            ),
        ),
        EffectSpec(
            "hose_compliance",
            "hose walls add compliance to the line and dead volumes (pressure-independent)",
            (
                ParamSpec(
                    "wall_modulus_gpa",
                    "GPa",
                    0.5,
                    0.1,
                    3.0,
                    "effective wall modulus of the hoses; 1/beta = 1/beta_oil + 1/E_wall",
                ),
                ParamSpec(
                    "line_capacitance_cm3_per_bar",
                    "cm^3/bar",
                    0.05,
                    0.0,
                    5.0,
                    "law added_capacitance: hose capacitance on the pump line",
                ),
                ParamSpec(
                    "cylinder_capacitance_cm3_per_bar",
                    "cm^3/bar",
                    0.05,
                    0.0,
                    5.0,
                    "law added_capacitance: hose capacitance on each cylinder line (A and B)",
                ),
            ),
            (
                ChoiceSpec(
                    "law",
                    ("series_modulus", "added_capacitance"),
                    "series_modulus",
                    "series_modulus: the walls soften each volume's oil (wall_modulus_gpa); "
                    "added_capacitance: hoses add a capacitance of their own per line",
                ),
            ),
        ),
        EffectSpec(
            "sensor_lag",
            "pressure and flow sensors report late: a transport delay and a first-order filter",
            (
                ParamSpec("delay_ms", "ms", 20.0, 0.0, 100.0, "pure delay of PP, PA, PB, QP"),
                ParamSpec("time_constant_ms", "ms", 0.0, 0.0, 200.0, "first-order filter"),
            ),
        ),
        EffectSpec(
            "load_variation",
            "gravity load on the rod changes with boom position (lever geometry): slope "
            "and curvature",
            (
                ParamSpec(
                    "slope_n_per_mm",
                    "N/mm",
                    8.0,
                    -20.0,
                    20.0,
                    "load change per mm of stroke about the reference position",
                ),
                ParamSpec(
                    "curvature_n_per_mm2",
                    "N/mm^2",
                    0.0,
                    -0.1,
                    0.1,
                    "quadratic term: load change of curvature x (mm from the reference)^2",
                ),
            ),
        ),
        EffectSpec(
            "sensor_calibration",
            "one measured signal reads gain x true + offset (after noise-free physics; the "
            "plant and the other signals are untouched)",
            (
                ParamSpec(
                    "gain",
                    "-",
                    1.1,
                    0.5,
                    1.5,
                    "reading per true value (1 when only offset is given)",
                ),
                ParamSpec(
                    "offset",
                    "signal unit",
                    0.0,
                    -50.0,
                    50.0,
                    "added to the reading, in bar (PP, PA, PB; within +-20), L/min (QP; "
                    "within +-10) or mm (RodPos; within +-50)",
                ),
            ),
            (ChoiceSpec("signal", tuple(SENSOR_CAL_SIGNALS), "PA", "the miscalibrated signal"),),
        ),
    )
}
assert tuple(CATALOGUE) == EFFECT_NAMES  # the contract's names, in its order
