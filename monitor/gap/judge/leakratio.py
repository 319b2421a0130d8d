"""A leak's level on the cold and on the warm part of a warm-up, against the ratio each
cause predicts: the most direct test of whether a leak follows the oil temperature.

A worn pump's slip is the same cold and warm (ratio 1); a laminar leak through thin oil
grows as the viscosity falls (ratio nu_cold / nu_warm).  The leak is fitted as a constant
on the coldest and on the warmest third of the segments (by their mean oil temperature),
each from its own segments, and their ratio is resampled over those segments.  Where both
laws fit the whole recording alike (a held-out comparison at one set of tolerances), the
two thirds' levels still part: this reads the leak's temperature law, not its total fit.

Each segment enters as the linearised least-squares sums of its residual in the leak
coefficient (``a = J.J``, ``b = J.r`` at the level ``leak0``): a set of segments' level is
``leak0 - sum(b) / sum(a)``, one Gauss-Newton step from ``leak0``, exact for a residual
linear in the leak (the leak flow is the coefficient times the pressure drop).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.gap.judge.decide import SIGNIFICANT

#: Resamples of the segments within each third.
RESAMPLES = 1000
#: Segments a third needs for its level to be resampled at all.
MIN_SEGMENTS = 3


@dataclass(frozen=True)
class LeakRatio:
    """The leak's level (L/min per 100 bar) on the cold and the warm third, their ratio
    (warm / cold) with its resampled 5th-95th percentile interval, and the ratio a leak
    following 1/viscosity would show between the same segments."""

    temps_c: tuple[float, float]
    leaks: tuple[float, float]
    ratio: float
    interval: tuple[float, float]
    viscous_ratio: float
    #: Share of resamples whose ratio is below the viscous one (the leak grew less than
    #: viscosity says), above 1 (it grew), and below the two's geometric mean (nearer 1).
    below_viscous: float
    above_one: float
    nearer_one: float

    @property
    def cause(self) -> str | None:
        """``wear`` (the interval excludes the viscous ratio, not 1), ``oil_viscosity``
        (it excludes 1, not the viscous ratio).  Excluding both (a leak that grew, less
        than viscosity says: a worn pump's constant slip beside a sound pump's viscous
        one) the ratio nearer on a log scale decides, where the interval lies on one side
        of their geometric mean.  None: it excludes neither, or straddles the mean."""
        wear, viscous = self.below_viscous >= SIGNIFICANT, self.above_one >= SIGNIFICANT
        if wear and viscous:
            wear, viscous = self.nearer_one >= SIGNIFICANT, self.nearer_one <= 1 - SIGNIFICANT
        if wear and not viscous:
            return "wear"
        if viscous and not wear:
            return "oil_viscosity"
        return None

    def as_dict(self) -> dict:
        return {
            "oil_temp_c": [round(t, 1) for t in self.temps_c],
            "leak_lpm_per_100bar": [round(v, 4) for v in self.leaks],
            "ratio": round(self.ratio, 3),
            "interval": [round(v, 3) for v in self.interval],
            "viscous_ratio": round(self.viscous_ratio, 3),
            "below_viscous_share": round(self.below_viscous, 3),
            "above_one_share": round(self.above_one, 3),
            "nearer_one_share": round(self.nearer_one, 3),
            "cause": self.cause,
        }

    def evidence(self) -> str:
        cold, warm = self.leaks
        lo, hi = self.interval
        return (
            f"fitted on its own, the leak is {cold:.2g} L/min per 100 bar on the cold third "
            f"(oil {self.temps_c[0]:.0f} degC) and {warm:.2g} on the warm third "
            f"({self.temps_c[1]:.0f} degC): {self.ratio:.2f}-fold (resampled {lo:.2f} to "
            f"{hi:.2f}), where a leak following 1/viscosity grows {self.viscous_ratio:.2f}-fold "
            "and a worn pump's stays 1"
        )


def leak_ratio(
    a: np.ndarray,
    b: np.ndarray,
    temps_c: np.ndarray,
    inv_nu: np.ndarray,
    leak0: float,
    seed: int = 0,
) -> LeakRatio | None:
    """The cold and warm thirds' leak levels from each segment's linearised sums ``a``,
    ``b`` at ``leak0``, its mean oil temperature ``temps_c`` (degC) and mean 1/viscosity
    ``inv_nu`` (any scale).  The viscous ratio weights each segment's 1/viscosity as the
    fit weights its level (by ``a``).  None: a third too small or without information."""
    order = np.argsort(temps_c, kind="stable")
    n = len(order) // 3
    if n < MIN_SEGMENTS:
        return None
    cold, warm = order[:n], order[-n:]
    if a[cold].sum() <= 0 or a[warm].sum() <= 0:
        return None

    def level(rows: np.ndarray) -> np.ndarray:
        """Per resample (rows: resamples x segments) the third's level."""
        return leak0 - b[rows].sum(axis=-1) / np.maximum(a[rows].sum(axis=-1), 1e-300)

    rng = np.random.default_rng(seed)
    lc, lw = level(cold), level(warm)
    boot_c = level(cold[rng.integers(0, n, (RESAMPLES, n))])
    boot_w = level(warm[rng.integers(0, n, (RESAMPLES, n))])
    # A level at or below zero has no ratio: it counts as no growth (below any ratio > 0).
    ratios = np.where(boot_c > 0, boot_w / np.where(boot_c > 0, boot_c, 1.0), 0.0)
    visc = float(
        (np.sum(a[warm] * inv_nu[warm]) / a[warm].sum())
        / (np.sum(a[cold] * inv_nu[cold]) / a[cold].sum())
    )
    return LeakRatio(
        temps_c=(float(np.mean(temps_c[cold])), float(np.mean(temps_c[warm]))),
        leaks=(float(lc), float(lw)),
        ratio=float(lw / lc) if lc > 0 else 0.0,
        interval=(float(np.percentile(ratios, 5)), float(np.percentile(ratios, 95))),
        viscous_ratio=visc,
        below_viscous=float(np.mean(ratios < visc)),
        above_one=float(np.mean(ratios > 1.0)),
        nearer_one=float(np.mean(ratios < np.sqrt(visc))),
    )
