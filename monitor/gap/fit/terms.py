"""The library of correction terms behind ``suggestion``: physical shapes a simulation
engineer can add to the model, each with one or two coefficients in a unit an engineer
reads.

A plant term maps its coefficients (reported units) to a changed machine (pump and valve
settings: ``MachineParams`` fields) and kernel corrections (``monitor.sim.corrections``,
SI); sensor terms act on the simulated readings only (``sensorterms.py``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from monitor.sim.machine import BAR, LPM, MachineParams

Apply = Callable[[MachineParams, np.ndarray], tuple[MachineParams, dict[str, float]]]


@dataclass(frozen=True)
class PlantTerm:
    """One correction of the plant: kind and what it acts on (the contract's ``term`` and
    ``signal``), its shape, coefficient unit, finite-difference steps and bounds."""

    kind: str
    signal: str
    shape: str
    unit: str
    steps: tuple[float, ...]
    low: tuple[float, ...]
    high: tuple[float, ...]
    apply: Apply
    frequency_hz: float | None = None  # the periodic force's

    @property
    def key(self) -> str:
        return f"{self.kind}:{self.signal}:{self.shape}"


def _corr(name: str, si_per_unit: float) -> Apply:
    return lambda m, c: (m, {name: float(c[0]) * si_per_unit})


def _shift(fields: tuple[str, ...], si_per_unit: float) -> Apply:
    """Machine fields shifted together by the coefficient (e.g. bar)."""

    def apply(m: MachineParams, c: np.ndarray) -> tuple[MachineParams, dict[str, float]]:
        d = float(c[0]) * si_per_unit
        return m.with_changes(**{f: m.value(f) + d for f in fields}), {}

    return apply


def _scale(field: str) -> Apply:
    """A machine field scaled by (1 + coefficient / 100)."""

    def apply(m: MachineParams, c: np.ndarray) -> tuple[MachineParams, dict[str, float]]:
        return m.with_changes(**{field: m.value(field) * (1.0 + float(c[0]) / 100.0)}), {}

    return apply


def periodic(omega_rad_s: float) -> PlantTerm:
    """A periodic force on the rod at a given angular frequency: cos and sin amplitudes (N),
    as a load (positive pushes the rod in)."""

    def apply(m: MachineParams, c: np.ndarray) -> tuple[MachineParams, dict[str, float]]:
        return m, {
            "force_cos": float(c[0]),
            "force_sin": float(c[1]),
            "force_omega": omega_rad_s,
        }

    return PlantTerm(
        "force_periodic",
        "rod",
        "a cos(wt) + b sin(wt)",
        "N",
        (200.0, 200.0),
        (-5000.0, -5000.0),
        (5000.0, 5000.0),
        apply,
        omega_rad_s / (2 * math.pi),
    )


# Leakage coefficients: L/min per 100 bar (laminar), L/min at 100 bar (orifice-like, and
# for the square law).
_LIN = LPM / (100 * BAR)
_SQRT = LPM / math.sqrt(100 * BAR)
_SQ = LPM / (100 * BAR) ** 2

_LEAKS = (("P->tank", "pt"), ("A->tank", "at"), ("B->tank", "bt"), ("A<->B", "ab"))


def _leakage_terms() -> list[PlantTerm]:
    out = []
    for path, code in _LEAKS:
        out.append(
            PlantTerm(
                "leakage",
                path,
                "dp",
                "L/min per 100 bar",
                (0.5,),
                (0.0,),
                (20.0,),
                _corr(f"leak_{code}_lin", _LIN),
            )
        )
        out.append(
            PlantTerm(
                "leakage",
                path,
                "sqrt(dp)",
                "L/min at 100 bar",
                (0.5,),
                (0.0,),
                (20.0,),
                _corr(f"leak_{code}_sqrt", _SQRT),
            )
        )
    out.append(
        PlantTerm(
            "leakage",
            "A->tank",
            "dp^2",
            "L/min at 100 bar",
            (0.5,),
            (0.0,),
            (20.0,),
            _corr("leak_at_sq", _SQ),
        )
    )
    return out


_EDGES = (("P->A", "pa"), ("P->B", "pb"), ("A->tank", "at"), ("B->tank", "bt"))


def library() -> list[PlantTerm]:
    """Every plant term but the periodic force (its frequency comes from the data)."""
    return [*_leakage_terms(), *_force_terms(), *_valve_terms(), *_pump_terms()]


def _force_terms() -> list[PlantTerm]:
    """Forces on the rod: viscous, Coulomb, and a spring about the mid stroke."""
    return [
        PlantTerm(
            "force_velocity",
            "rod",
            "c v",
            "N s/m",
            (300.0,),
            (-5000.0,),
            (5000.0,),
            _corr("force_velocity", 1.0),
        ),
        PlantTerm(
            "force_sign",
            "rod",
            "F sign(v)",
            "N",
            (200.0,),
            (-3000.0,),
            (3000.0,),
            _corr("force_sign", 1.0),
        ),
        PlantTerm(
            "force_position",
            "rod",
            "k (x - x_ref)",
            "N/mm",
            (2.0,),
            (-50.0,),
            (50.0,),
            _corr("force_position", 1e3),
        ),
    ]


def _valve_terms() -> list[PlantTerm]:
    """A gain change of each metering edge of the valve."""
    return [
        PlantTerm(
            "valve_setting",
            edge,
            "edge gain",
            "% change",
            (5.0,),
            (-90.0,),
            (100.0,),
            _corr(f"kv_{code}_rel", 0.01),
        )
        for edge, code in _EDGES
    ]


def _pump_terms() -> list[PlantTerm]:
    """The pump's compensator, displacement and relief settings."""
    return [
        PlantTerm(
            "pump_setting",
            "compensator",
            "start and full pressure shift",
            "bar",
            (3.0,),
            (-40.0,),
            (40.0,),
            _shift(("compensator_start_pa", "compensator_full_pa"), BAR),
        ),
        PlantTerm(
            "pump_setting",
            "displacement",
            "max displacement",
            "% change",
            (3.0,),
            (-30.0,),
            (30.0,),
            _scale("pump_disp_m3_rev"),
        ),
        PlantTerm(
            "pump_setting",
            "relief",
            "crack and full pressure shift",
            "bar",
            (3.0,),
            (-40.0,),
            (40.0,),
            _shift(("relief_crack_pa", "relief_full_pa"), BAR),
        ),
    ]


def describe(term: PlantTerm, c: np.ndarray) -> tuple[float, str]:
    """The reported coefficient and one line an engineer reads."""
    if term.kind == "force_periodic":
        amp = float(math.hypot(c[0], c[1]))
        phase = math.degrees(math.atan2(-c[1], c[0]))
        return amp, (
            f"periodic load on the rod: {amp:.0f} N amplitude at {term.frequency_hz:.4g} Hz "
            f"(phase {phase:+.0f} deg at t = 0 s of the recording)"
        )
    v = float(c[0])
    if term.kind == "leakage":
        return v, f"leakage {term.signal} proportional to {term.shape}: {v:.3g} {term.unit}"
    if term.kind == "force_velocity":
        return v, f"extra viscous friction on the rod: {v:+.0f} {term.unit}"
    if term.kind == "force_sign":
        return v, f"extra Coulomb friction on the rod: {v:+.0f} {term.unit}"
    if term.kind == "force_position":
        return v, f"position-dependent load on the rod: {v:+.3g} {term.unit} about the reference"
    if term.kind == "valve_setting":
        return v, f"valve edge {term.signal} flow gain {v:+.1f} %"
    return v, f"pump {term.signal} ({term.shape}): {v:+.3g} {term.unit}"
