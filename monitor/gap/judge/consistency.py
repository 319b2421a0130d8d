"""An effect's fingerprint across the signals: a physical effect that is really there moves
every signal it acts on towards the recording, or leaves it alone; it does not buy a
smaller gap in some signals with a clearly larger one in another.

A catalogue effect is one piece of the machine's physics, and that physics couples the
signals: a pump leak that lowers PP in the compensator range also takes flow from QP
wherever the pump runs at full displacement; thinner oil leaks across every path and
moves the friction with the temperature.  When the machine has the effect, the fitted
member reproduces all of that, so no compared signal ends up further from the recording
than the calibrated simulator left it (a formulation other than ours leaves a remainder,
small against the gap).  When the gap is something else (a base mismatch: the simulator's
pump reads 10 bar low in its compensator range while the boom is lowered), an effect can
still be fitted to the signals where that gap lives, but its physics then drags another
signal away from the recording: a healthy machine without RodPos was named
``oil_viscosity`` (pump leak) with PP and PB closer and QP's NRMSE 1.34 times what the
calibrated simulator left.  Such a fit stands in for a mismatch; it is not the effect.

*Clearly worse*: the signal's held-out mean squared residual above the noise grows by at
least ``WORSE_MATERIAL`` of the calibrated simulator's whole gap (the share a second
effect must remove to be named: less is the remainder any formulation mismatch leaves)
and it grows in at least the verdict's significance share of the block-bootstrap
resamples (``decide.SIGNIFICANT``).  A sensor calibration is judged by its own rule
(``sensorphysics.py``): it moves one signal only by construction.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.gap.fit.score import SegmentSums
from monitor.gap.judge.shrink import boot_mse

#: A signal's excess over the noise must grow by this share of the whole held-out gap ...
WORSE_MATERIAL = 0.05


@dataclass
class Worse:
    """The compared signal an effect makes clearly worse."""

    signal: int  # column of the sums
    growth: float  # growth of its excess over the noise, as a share of the whole gap
    share: float  # share of bootstrap resamples in which it grows


def worse_signal(
    before: SegmentSums,
    after: SegmentSums,
    idx: np.ndarray,
    floor: np.ndarray,
    significant: float,
) -> Worse | None:
    """The signal ``after`` (the effect added) leaves clearly further from the recording
    than ``before`` (the calibrated simulator), the one with the largest growth; None when
    no signal is."""
    ex0 = np.maximum(before.mse() - floor, 0.0)
    ex1 = np.maximum(after.mse() - floor, 0.0)
    whole = float(ex0.sum())
    if whole <= 0.0:
        return None
    growth = (ex1 - ex0) / whole
    b0 = np.maximum(boot_mse(before, idx) - floor, 0.0)
    b1 = np.maximum(boot_mse(after, idx) - floor, 0.0)
    share = np.mean(b1 > b0, axis=0)
    bad = (growth >= WORSE_MATERIAL) & (share >= significant)
    if not bad.any():
        return None
    j = int(np.argmax(np.where(bad, growth, -np.inf)))
    return Worse(j, float(growth[j]), float(share[j]))
