"""Bounded least squares over named physical parameters (scipy.optimize.least_squares).

Each parameter is mapped to [0, 1] (logarithmically for ranges over a decade or more), so
one finite-difference step and one trust region suit them all.  A few starting points are
tried first, and the fit starts from the best (or the best few): the objectives have
local minima (a delay, a deadband, friction against viscous friction) that a single local
start can miss.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares


@dataclass(frozen=True)
class Knob:
    """A fitted parameter: name, bounds in its own unit, log or linear mapping."""

    name: str
    low: float
    high: float
    log: bool = False

    def value(self, u: float) -> float:
        u = min(max(u, 0.0), 1.0)
        if self.log:
            return math.exp(math.log(self.low) + u * (math.log(self.high) - math.log(self.low)))
        return self.low + u * (self.high - self.low)

    def unit(self, value: float) -> float:
        value = min(max(value, self.low), self.high)
        if self.log:
            return (math.log(value) - math.log(self.low)) / (
                math.log(self.high) - math.log(self.low)
            )
        return (value - self.low) / (self.high - self.low)


@dataclass
class FitResult:
    values: dict[str, float]
    cost: float  # mean squared residual at the fitted values
    evaluations: int


#: Iterations of the trust-region solver (each costs 1 + len(knobs) simulations).
MAX_ITERATIONS = 6
#: Finite-difference step in the unit interval.
DIFF_STEP = 0.03


def default_starts(n: int) -> list[np.ndarray]:
    """Low, middle and high, plus the corners' mixtures for two parameters."""
    if n == 1:
        return [np.array([u]) for u in (0.1, 0.4, 0.8)]
    base = [np.full(n, u) for u in (0.2, 0.5, 0.8)]
    if n == 2:
        base += [np.array([0.2, 0.8]), np.array([0.8, 0.2])]
    return base


def fit(
    residual: Callable[[dict[str, float]], np.ndarray],
    knobs: Sequence[Knob],
    starts: Sequence[dict[str, float]] | None = None,
    max_iterations: int = MAX_ITERATIONS,
    local_starts: int = 1,
) -> FitResult:
    """Minimise ``sum(residual(values)**2)`` with every knob inside its bounds, by local
    fits from the ``local_starts`` best starting points (the best result kept)."""
    calls = 0

    def values_of(u: np.ndarray) -> dict[str, float]:
        return {k.name: k.value(float(x)) for k, x in zip(knobs, u, strict=True)}

    def fun(u: np.ndarray) -> np.ndarray:
        nonlocal calls
        calls += 1
        return residual(values_of(u))

    if starts is None:
        points = default_starts(len(knobs))
    else:
        points = [np.array([k.unit(s[k.name]) for k in knobs]) for s in starts]
    costs = [float(np.mean(fun(p) ** 2)) for p in points]
    best_u, best_cost = points[int(np.argmin(costs))], min(costs)
    for i in np.argsort(costs, kind="stable")[: max(local_starts, 1)]:
        res = least_squares(
            fun,
            points[i],
            bounds=(np.zeros(len(knobs)), np.ones(len(knobs))),
            diff_step=DIFF_STEP,
            max_nfev=max_iterations,
            xtol=1e-3,
            ftol=1e-4,
        )
        cost = float(np.mean(res.fun**2))
        if cost < best_cost:
            best_u, best_cost = res.x, cost
    return FitResult(values_of(best_u), best_cost, calls)
