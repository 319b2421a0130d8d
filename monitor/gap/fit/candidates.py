"""Which effect: add each catalogue effect in turn, fit it on the calibration part, score it
on the held-out part, and rank with a penalty for the parameters it adds.

The penalty is a Bayesian information criterion on the held-out gap (plus the noise
floor) with the sample size corrected for autocorrelation (residuals of a dynamic model
are strongly correlated at 100 Hz, so the raw sample count would make any extra parameter
look free).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from monitor.gap.data.prepare import Prepared
from monitor.gap.fit.calibrate import AT_BOUND_SHARE, TOLERANCES
from monitor.gap.fit.solve import MAX_ITERATIONS, Knob, default_starts, fit
from monitor.sim.effects import CATALOGUE, Effect

#: Fitted parameters per effect; the others keep their catalogue defaults (weakly
#: identifiable from the four signals: an oil's reference viscosities, a gas exponent).
KNOBS: dict[str, tuple[Knob, ...]] = {
    "entrained_air": (Knob("air_fraction", 0.0005, 0.1, log=True),),
    "oil_viscosity": (
        Knob("pump_leak_lpm_per_100bar", 0.0, 5.0),
        Knob("friction_share", 0.0, 1.0),
    ),
    "cylinder_friction": (
        Knob("coulomb_n", 0.0, 3000.0),
        Knob("static_excess_n", 0.0, 2000.0),
    ),
    "spool_dynamics": (
        Knob("natural_freq_hz", 2.0, 40.0, log=True),
        Knob("damping_ratio", 0.3, 1.5),
    ),
    "valve_deadband": (Knob("overlap_pct", 0.0, 30.0),),
    "pump_control_dynamics": (Knob("time_constant_ms", 5.0, 500.0, log=True),),
    "hose_compliance": (Knob("wall_modulus_gpa", 0.1, 3.0, log=True),),
    "sensor_lag": (Knob("delay_ms", 0.0, 100.0), Knob("time_constant_ms", 0.0, 200.0)),
    "load_variation": (Knob("slope_n_per_mm", -20.0, 20.0),),
    # Fitted in closed form, one signal at a time (sensorcal.py); listed for the penalty.
    "sensor_calibration": (Knob("gain", 0.5, 1.5), Knob("offset", -50.0, 50.0)),
}
assert set(KNOBS) == set(CATALOGUE)

#: Tolerances an effect trades off against, fitted together with it: the calibration
#: soaks up what it can of an effect (entrained air looks like larger volumes within
#: their band, a deadband like a weaker valve, Coulomb friction like more viscous friction
#: and a weaker valve, both slowing the rod; at reversals it also passes for a lighter
#: boom: the other team's plant calibrated mass to -15 % under a 400 N friction), and an
#: effect fitted on top of that calibration would be scored against a machine already bent
#: towards it.
CONFOUNDED: dict[str, tuple[str, ...]] = {
    "entrained_air": ("volumes",),
    "hose_compliance": ("volumes",),
    "valve_deadband": ("valve_gain", "valve_metering"),
    "cylinder_friction": ("viscous_friction", "valve_gain", "mass"),
    "oil_viscosity": ("viscous_friction",),
    "load_variation": ("gravity_load",),
}
assert {t for ts in CONFOUNDED.values() for t in ts} <= {t.name for t in TOLERANCES}


@dataclass(frozen=True)
class Member:
    """One formulation within an effect's family: the parameters it fixes (values in the
    catalogue's units, or a named choice such as a mixture law) and the knobs it fits."""

    name: str
    knobs: tuple[Knob, ...]
    fixed: tuple[tuple[str, float | str], ...] = ()
    #: A knob whose lower bound is the least this formulation stands for: a fit that ends
    #: there asked for less, which the family's default answers (``families.fit_family``).
    floor: str | None = None
    #: Starting points (knob values in their units, in ``knobs``' order) instead of the
    #: fit's default low-middle-high ones: for objectives with many minima along a knob,
    #: such as a ringing's frequency.
    starts: tuple[tuple[float, ...], ...] = ()

    def start_units(self) -> list[np.ndarray]:
        """``starts`` in the unit interval of each knob."""
        return [
            np.array([k.unit(v) for k, v in zip(self.knobs, p, strict=True)]) for p in self.starts
        ]

    def at_floor(self, effect: Effect) -> bool:
        """Whether ``effect`` (fitted with this member) ended on the floor knob's bound (as
        close to it as a tolerance at its bound: the solver stops just inside)."""
        if self.floor is None:
            return False
        knob = next(k for k in self.knobs if k.name == self.floor)
        return knob.unit(float(effect.params[self.floor])) <= 1.0 - AT_BOUND_SHARE


#: Name of the formulation ``KNOBS`` fits, per effect (the catalogue's defaults otherwise).
DEFAULT_MEMBER: dict[str, str] = {
    "entrained_air": "free_air",
    "oil_viscosity": "pump_leak",
    "cylinder_friction": "stribeck",
    "load_variation": "linear",
    "hose_compliance": "series_modulus",
    "pump_control_dynamics": "first_order",
}


def default_member(name: str) -> Member:
    return Member(DEFAULT_MEMBER.get(name, "default"), KNOBS[name])


def make_effect(name: str, values: dict[str, float], member: Member | None = None) -> Effect:
    """The catalogue effect for fitted knob values (knob names are the effect's, except
    ``static_excess_n``, which keeps static friction at or above Coulomb friction), with
    the parameters ``member`` fixes."""
    params: dict[str, float | str] = dict(member.fixed) if member is not None else {}
    params.update(values)
    if name == "cylinder_friction":
        extra = float(params.pop("static_excess_n"))
        high = CATALOGUE[name].param("static_n").high
        params["static_n"] = min(float(params["coulomb_n"]) + extra, high)
    return Effect.make(name, **params)


def knob_values(effect: Effect, member: Member | None = None) -> dict[str, float]:
    """Inverse of ``make_effect``: a fitted effect's values as knob values (a fit's start)."""
    knobs = member.knobs if member is not None else KNOBS[effect.name]
    values = {k.name: effect.params.get(k.name, 0.0) for k in knobs}
    if effect.name == "cylinder_friction":
        values["static_excess_n"] = effect.params["static_n"] - effect.params["coulomb_n"]
    return values


def n_params(effects: Sequence[Effect], members: Sequence[Member] = ()) -> int:
    """Fitted parameters of the effects (their members' knobs where given)."""
    if members:
        return sum(len(m.knobs) for m in members)
    return sum(len(KNOBS[e.name]) for e in effects)


@dataclass(eq=False)
class Candidate:
    """One fitted hypothesis: its effects, the tolerance factors it was fitted with, and its
    held-out scores."""

    effects: tuple[Effect, ...]
    factors: dict[str, float]
    fit_cost: float
    members: tuple[Member, ...] = ()  # per effect; empty: the default formulations
    heldout_mse: np.ndarray = field(default_factory=lambda: np.zeros(0))
    heldout_gap: float = 0.0
    heldout_reduction: float = 0.0
    criterion: float = 0.0
    #: The recording as this hypothesis reads it, when that differs from the diagnosis's
    #: (a QP calibration without RodPos rereads the rod path: ``reread.py``); None: as
    #: prepared.
    prep: Prepared | None = None

    @property
    def name(self) -> str:
        return "+".join(e.name for e in self.effects)


Residual = Callable[[dict[str, float], tuple[Effect, ...]], np.ndarray]


def fit_candidate(
    names: Sequence[str],
    residual: Residual,
    factors: dict[str, float],
    tolerances: Sequence[Knob] = (),
    starts: Sequence[tuple[dict[str, float], Sequence[Effect]]] | None = None,
    max_iterations: int = MAX_ITERATIONS,
    local_starts: int = 1,
    members: Sequence[Member] | None = None,
) -> Candidate:
    """Fit the knobs of the effects ``names`` (and the ``tolerances`` knobs, if given,
    jointly; otherwise at ``factors``).  ``starts`` are (factors, effects) to start from;
    local fits run from the ``local_starts`` best of them.  ``members`` (one per name) picks
    each effect's formulation; by default the one ``KNOBS`` fits."""
    mem = list(members) if members else [default_member(n) for n in names]
    eff_knobs = [
        Knob(f"{n}.{k.name}", k.low, k.high, k.log)
        for n, m in zip(names, mem, strict=True)
        for k in m.knobs
    ]
    knobs = [*tolerances, *eff_knobs]

    def split(values: dict[str, float]) -> tuple[dict[str, float], tuple[Effect, ...]]:
        f = dict(factors)
        f.update({k.name: values[k.name] for k in tolerances})
        fx = tuple(
            make_effect(n, {k.name: values[f"{n}.{k.name}"] for k in m.knobs}, m)
            for n, m in zip(names, mem, strict=True)
        )
        return f, fx

    start_points = None
    own_starts = len(mem) == 1 and bool(mem[0].starts)
    if starts is None and (tolerances or own_starts):
        # The effect's default starts with the tolerances both where the calibration put
        # them and at nominal: a calibration that pushed a tolerance to its bound to mimic
        # the effect would otherwise start every fit in the effect's shadow.
        # A shape the calibration took up (the valve's notches) is also started from its
        # nominal with the rest calibrated: notches stand in for an overlap, and a
        # deadband fitted on top of them ends beside them.
        units = mem[0].start_units() if own_starts else default_starts(len(eff_knobs))
        start_points = _default_starts(factors, tolerances, eff_knobs, units)
    elif starts is not None:
        start_points = []
        for f0, fx0 in starts:
            point = {k.name: f0.get(k.name, 1.0) for k in tolerances}
            for e, m in zip(fx0, mem, strict=True):
                point.update({f"{e.name}.{k}": v for k, v in knob_values(e, m).items()})
            start_points.append(point)
    result = fit(lambda v: residual(*split(v)), knobs, start_points, max_iterations, local_starts)
    f, fx = split(result.values)
    return Candidate(fx, f, result.cost, tuple(mem) if members else ())


#: Tolerances that are a shape added to the nominal machine (``Tolerance.added``).
SHAPES = frozenset(t.name for t in TOLERANCES if t.added)


def _default_starts(
    factors: dict[str, float],
    tolerances: Sequence[Knob],
    eff_knobs: Sequence[Knob],
    units: Sequence[np.ndarray],
) -> list[dict[str, float]]:
    """The effect's starting ``units`` with the tolerances calibrated, at nominal, and (a
    shape the calibration took up) with the shape at nominal."""
    shapes = {k.name for k in tolerances if k.name in SHAPES and factors.get(k.name, 1.0) > 1}
    places = ("cal", "nominal", "shape") if shapes else ("cal", "nominal")
    return [
        {
            **{k.name: _start(k.name, factors, at, shapes) for k in tolerances},
            **{k.name: k.value(float(x)) for k, x in zip(eff_knobs, u, strict=True)},
        }
        for at in (places if tolerances else ("cal",))
        for u in units
    ]


def _start(name: str, factors: dict[str, float], at: str, shapes: set[str]) -> float:
    """A tolerance's starting factor: calibrated, nominal, or nominal if a shape (``at``)."""
    if at == "nominal" or (at == "shape" and name in shapes):
        return 1.0
    return factors.get(name, 1.0)


def criterion(gap: float, floor: np.ndarray, n_eff: float, k: int) -> float:
    """BIC with the effective sample size on the held-out gap plus the noise a perfect
    simulator leaves: n_eff ln(gap + sum(floor)) + k ln(n_eff).

    The same quantity as the reduction and the bootstrap confidence (the gap above the
    noise), so the ranking and the confidence cannot favour different effects except by
    the penalty for parameters."""
    return n_eff * math.log(max(gap + float(np.sum(floor)), 1e-300)) + k * math.log(n_eff)
