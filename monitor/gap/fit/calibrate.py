"""Tolerances first: fit the nominal machine's parameters within their tolerance bands.

A real machine differs from the nominal values by a few percent; if the tool did not
calibrate those first, a heavier boom or a stiffer valve would be taken for a missing
effect.  The bands are wider than the few percent a machine varies by, narrower than what
an effect would need to hide in them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.gap.fit.solve import Knob
from monitor.sim.machine import MachineParams


@dataclass(frozen=True)
class Tolerance:
    """A relative band around the nominal value of one or more machine fields."""

    name: str
    fields: tuple[str, ...]
    unit: str
    to_unit: float  # SI value times this gives the reported unit
    band: float  # +- fraction of nominal
    #: Added, not multiplied: the field is the nominal plus ``factor - 1`` (a shape whose
    #: nominal is 0), and only upwards (``1 .. 1 + band``).
    added: bool = False

    def knob(self) -> Knob:
        return Knob(self.name, 1.0 if self.added else 1.0 - self.band, 1.0 + self.band)

    def field_value(self, nominal: float, factor: float) -> float:
        return nominal + (factor - 1.0) if self.added else nominal * factor


#: Gravity load and valve gain cover a machine of +-15 %, like mass and volumes: with
#: +-10 %, healthy machines whose valve gain was 12-14 % off the nominal were left with a
#: gap the bands could not follow, which an effect then took (or none explained).
TOLERANCES: tuple[Tolerance, ...] = (
    Tolerance("mass", ("mass_kg",), "kg", 1.0, 0.15),
    Tolerance("gravity_load", ("gravity_load_n",), "N", 1.0, 0.15),
    Tolerance("viscous_friction", ("viscous_friction_n_s_m",), "N s/m", 1.0, 0.30),
    Tolerance("valve_gain", ("valve_rated_flow_m3_s",), "L/min at rated dp", 6e4, 0.15),
    Tolerance(
        "volumes",
        ("dead_volume_a_m3", "dead_volume_b_m3", "line_volume_m3"),
        "L (cap-side dead volume)",
        1e3,
        0.15,
    ),
    # The valve's metering curve: notches over up to 60 % of the stroke on top of the
    # configured valve.  Mobile valves meter through notches; a linear simulator beside
    # one reads the small flows at small commands as an overlap (the fourth plant's
    # healthy machines were all named a deadband of 14-21 %).  An overlap passes nothing
    # below it; notches pass a small flow growing with the square of the opening
    # (``judge/heldflow.py`` reads which).
    Tolerance("valve_metering", ("notch_share",), "share of the stroke notched", 1.0, 0.6, True),
)


def apply(machine: MachineParams, factors: dict[str, float]) -> MachineParams:
    """``machine`` with every tolerance field multiplied by its factor (missing: 1)."""
    changes: dict[str, float] = {}
    for tol in TOLERANCES:
        f = factors.get(tol.name, 1.0)
        for name in tol.fields:
            changes[name] = tol.field_value(machine.value(name), f)
    return machine.with_changes(**changes)


def knobs(fitted: dict[str, float] | None = None, shapes: bool = True) -> list[Knob]:
    """Every tolerance as a fitted factor (1 = nominal) within its band: only those in
    ``fitted`` (a calibration's factors) if given; without the shapes (``Tolerance.added``,
    held at nominal) unless ``shapes``."""
    return [
        t.knob()
        for t in TOLERANCES
        if (fitted is None or t.name in fitted) and (shapes or not t.added)
    ]


#: A factor this close to the edge of its band (as a share of the band) ended at its bound.
AT_BOUND_SHARE = 0.98

BY_NAME = {t.name: t for t in TOLERANCES}

#: A shape tolerance (``Tolerance.added``: its nominal is its bound) the calibration took up
#: this much of its band or more ...
SHAPE_TAKEN_SHARE = 0.1
#: ... is given back by an effect's fit that leaves this share of it or less (a 6 % overlap
#: on a linear valve: the calibration took notches over 13 % of the stroke, the deadband's
#: joint fit 3 %).
SHAPE_LEFT_SHARE = 0.5


def gave_back(name: str, calibrated: float, fitted: float) -> bool:
    """Whether an effect's fit (``fitted`` factor) gave back the shape the calibration
    (``calibrated``) took up for tolerance ``name``: the calibration absorbed the effect."""
    t = BY_NAME[name]
    taken = calibrated - 1.0
    return (
        t.added and taken >= SHAPE_TAKEN_SHARE * t.band and fitted - 1.0 <= SHAPE_LEFT_SHARE * taken
    )


def bound_side(name: str, factor: float) -> int:
    """+1 or -1 when tolerance ``name``'s factor ended at its upper or lower bound, else 0."""
    excess = factor - 1.0
    return int(np.sign(excess)) if abs(excess) >= AT_BOUND_SHARE * BY_NAME[name].band else 0


def describe(machine: MachineParams, factors: dict[str, float]) -> dict[str, dict]:
    """The JSON form: value, unit, nominal, change in percent per tolerance, and whether the
    fit ended at the band's bound (the machine is outside the tolerance the simulator's
    configuration assumes, or the band took up part of an effect: either way the user is
    told rather than the gap silently absorbed)."""
    out = {}
    for tol in TOLERANCES:
        f = factors.get(tol.name, 1.0)
        nominal = machine.value(tol.fields[0]) * tol.to_unit
        out[tol.name] = {
            "value": round(tol.field_value(nominal, f), 6),
            "unit": tol.unit,
            "nominal": round(nominal, 6),
            "change_pct": round(100 * (f - 1), 2),
            "band_pct": round(100 * tol.band, 1),
            "at_bound": bound_side(tol.name, f) != 0,
        }
    return out
