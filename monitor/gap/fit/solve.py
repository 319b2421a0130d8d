"""Bounded least squares over named physical parameters (scipy.optimize.least_squares).

Each parameter is mapped to [0, 1] (logarithmically for ranges over a decade or more), so
one finite-difference step and one trust region suit them all.  A few starting points are
tried first, and the fit starts from the best (or the best few): the objectives have
local minima (a delay, a deadband, friction against viscous friction) that a single local
start can miss.

Every evaluation is a simulation of the calibration segments, so the Jacobian is estimated
by finite differences once per local fit and then kept up to date by Broyden's rank-one
update from the steps the solver takes (a finite-difference Jacobian at every iteration
cost 1 + n simulations per iteration, 60 % of a diagnosis).
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
            v = math.exp(math.log(self.low) + u * (math.log(self.high) - math.log(self.low)))
            # exp(log(5)) is 4.999999999999999: a fit at its bound would hand the effect a
            # value just outside its range, which the catalogue refuses (exit 2).
            return min(max(v, self.low), self.high)
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
    fits from the ``local_starts`` best starting points (the best result kept).  With
    ``max_iterations`` 0, only the starting points are evaluated and the best returned."""
    calls = 0

    def values_of(u: np.ndarray) -> dict[str, float]:
        return {k.name: k.value(float(x)) for k, x in zip(knobs, u, strict=True)}

    def fun(u: np.ndarray) -> np.ndarray:
        nonlocal calls
        calls += 1
        return residual(values_of(u))

    jac = _BroydenJacobian(fun)
    if starts is None:
        points = default_starts(len(knobs))
    else:
        points = [np.array([k.unit(s[k.name]) for k in knobs]) for s in starts]

    def local(u: np.ndarray, budget: int) -> tuple[np.ndarray, float]:
        jac.reset()
        res = least_squares(
            jac.value,
            u,
            jac=jac,
            bounds=(np.zeros(len(knobs)), np.ones(len(knobs))),
            max_nfev=budget,
            xtol=1e-3,
            ftol=1e-4,
        )
        return res.x, float(np.mean(res.fun**2))

    costs = [float(np.mean(jac.value(p) ** 2)) for p in points]
    best_u, best_cost = points[int(np.argmin(costs))], min(costs)
    if max_iterations <= 0:  # a screen: the best starting point, no local fit
        return FitResult(values_of(best_u), best_cost, calls)
    for i in np.argsort(costs, kind="stable")[: max(local_starts, 1)]:
        u, cost = local(points[i], max_iterations)
        if cost < best_cost:
            best_u, best_cost = u, cost
    # A Broyden Jacobian can point the wrong way near a minimum (a secant across it), where
    # the solver then stalls: a second, shorter round from a fresh one polishes.  Only the
    # best local fit is polished (polishing every one cost a tenth of a diagnosis, and on
    # the reference recordings it never changed which local fit was best).
    u, cost = local(best_u, max(2, max_iterations // 2))
    if cost < best_cost:
        best_u, best_cost = u, cost
    return FitResult(values_of(best_u), best_cost, calls)


class _BroydenJacobian:
    """A residual function's Jacobian for ``least_squares``: forward differences (step
    ``DIFF_STEP``, taken inwards at a bound) at the first point, then Broyden's rank-one
    update from the current point to every point the solver tries (rejected steps
    included).  Residuals are remembered, so the updates cost no simulation."""

    def __init__(self, fun: Callable[[np.ndarray], np.ndarray]):
        self._fun = fun
        self._seen: dict[bytes, np.ndarray] = {}
        self.reset()

    def reset(self) -> None:
        self._x: np.ndarray | None = None
        self._f: np.ndarray | None = None
        self._j: np.ndarray | None = None

    def value(self, u: np.ndarray) -> np.ndarray:
        u = np.asarray(u, dtype=np.float64)
        key = u.tobytes()
        if key not in self._seen:
            self._seen[key] = np.asarray(self._fun(u), dtype=np.float64)
            self._update(u, self._seen[key])
        return self._seen[key]

    def _update(self, u: np.ndarray, f: np.ndarray) -> None:
        """Broyden's update from the current point to ``u`` (rejected trial steps too)."""
        if self._j is None or self._x is None or self._f is None:
            return
        dx = u - self._x
        dd = float(dx @ dx)
        if dd > 0.0:
            self._j += np.outer(f - self._f - self._j @ dx, dx / dd)

    def __call__(self, u: np.ndarray) -> np.ndarray:
        u = np.asarray(u, dtype=np.float64)
        f = self.value(u)
        if self._j is None:
            j = np.empty((f.size, u.size))
            for i in range(u.size):
                h = DIFF_STEP if u[i] + DIFF_STEP <= 1.0 else -DIFF_STEP
                x = u.copy()
                x[i] += h
                j[:, i] = (self.value(x) - f) / h
            self._j = j
        self._x, self._f = u.copy(), f
        return self._j
