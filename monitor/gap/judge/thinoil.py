"""A thin oil told from a worn pump where the oil stays warm: what else the oil moves.

A leak that follows the oil temperature is viscosity, one that does not is wear
(``diagnose/cause.py``); on a machine whose oil stays within a few degrees the leak alone
cannot say which.  But a thinner oil does not only leak more: the viscous part of the
rod's friction (the seals' and the guide's oil films) falls with the viscosity, while a
worn pump leaves the rod alone.  So the rod's viscous friction is read from its measured
force balance (``friction.balance_sums``: F = G + k (x - x_ref) + c v + F_c sign(v) + m a
+ r v |v| over the moving samples, with c free and r, the drop between the chambers and
the pressure sensors, at zero or more), bootstrapped over the segments, and compared with
the least the simulator's tolerance band allows a machine with the configured oil
(``calibrate.TOLERANCES``: the configured viscous friction less 30 %).  Below it in
``SIGNIFICANT`` of the resamples, the oil is thinner than the configured one: a cause that
explains the leak and the friction together, where wear explains the leak only.  Within
the band nothing is decided (a thin oil whose friction is mostly not viscous looks the
same), and the verdict keeps the cause undecided.

Measured on our simulator (boom cycle at 55-56 degC, ISO VG 46, 3 L/min per 100 bar):
all of the viscous friction following the oil, 1133 N s/m (1070-1192 in 95 % of
resamples) against 1400; half of it, 1625; a worn pump's constant leak 2086; healthy 2043.
Read only with a measured RodPos: with the rod integrated from the pump flow the third
plant's balance read healthy machines' viscous friction at 0.5-0.75 of what it read with
RodPos, below the band on several (a worn pump there would have been called thin oil).

No simulation: the recording alone.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from monitor.gap.data.prepare import Prepared
from monitor.gap.data.segments import Segment
from monitor.gap.fit.calibrate import BY_NAME
from monitor.gap.judge.decide import SIGNIFICANT
from monitor.gap.judge.friction import MAX_RMS_N, MIN_SAMPLES, VISCOUS, balance_sums, readout
from monitor.gap.judge.shrink import resamples
from monitor.sim.machine import MachineParams


@dataclass(frozen=True)
class ThinOil:
    """The rod's viscous friction against what the configured oil allows."""

    #: The viscous coefficient the force balance shows (N s/m, free), and its 2.5th and
    #: 97.5th percentiles over the resamples.
    viscous_n_s_m: float
    interval_n_s_m: tuple[float, float]
    #: The least the tolerance band allows with the configured oil (N s/m).
    band_low_n_s_m: float
    #: Share of resamples with the viscous coefficient below ``band_low_n_s_m``.
    below_share: float
    rms_n: float
    samples: int
    #: Why the balance was not read (None: read).
    unread: str | None = None

    @property
    def thin(self) -> bool:
        """The oil is thinner than the configured one (the rod's viscous friction below
        what the band allows in ``SIGNIFICANT`` of the resamples)."""
        return self.unread is None and self.below_share >= SIGNIFICANT

    def evidence(self) -> str:
        if self.unread is not None:
            return f"the rod's viscous friction not read: {self.unread}"
        lo, hi = self.interval_n_s_m
        what = (
            "a thinner oil than the configured one, which leaks more everywhere"
            if self.thin
            else "not clearly below what the configured oil allows"
        )
        return (
            f"the rod's force balance shows viscous friction {self.viscous_n_s_m:.0f} N s/m "
            f"({lo:.0f}-{hi:.0f} in 95 % of resamples), below the {self.band_low_n_s_m:.0f} "
            f"the configured oil allows in {100 * self.below_share:.0f} % of resamples: {what}"
        )

    def as_dict(self) -> dict:
        return {
            "viscous_n_s_m": _num(self.viscous_n_s_m),
            "viscous_interval_n_s_m": [_num(v) for v in self.interval_n_s_m],
            "band_low_n_s_m": _num(self.band_low_n_s_m),
            "below_share": round(self.below_share, 3),
            "rms_n": _num(self.rms_n),
            "samples": self.samples,
            "thin": self.thin,
            "evidence": self.evidence(),
        }


def signature(prep: Prepared, segments: Sequence[Segment], machine: MachineParams) -> ThinOil:
    """The rod's viscous friction from its measured force balance, bootstrapped over
    ``segments``, against the configured viscous friction less its tolerance band."""
    low = machine.load.viscous_friction_n_s_m * (1.0 - BY_NAME["viscous_friction"].band)
    if not prep.has_rodpos:
        return _unread(low, "no RodPos (a rod integrated from the pump flow reads it low)")
    xtx, xty, yty, n = balance_sums(prep, segments, machine)
    total = int(n.sum())
    if total < MIN_SAMPLES:
        return _unread(low, f"{total} moving samples (need {MIN_SAMPLES})", samples=total)
    a, b = xtx.sum(axis=0), xty.sum(axis=0)
    beta = readout(a, b)
    rms = float(np.sqrt(max(float(yty.sum()) - 2 * beta @ b + beta @ a @ beta, 0.0) / total))
    if rms > MAX_RMS_N:
        return _unread(low, f"the balance leaves {rms:.0f} N rms", rms, total)
    boot = np.array(
        [
            readout(xtx[i].sum(axis=0), xty[i].sum(axis=0))[VISCOUS]
            for i in resamples(len(segments), seed=1)
        ]
    )
    return ThinOil(
        viscous_n_s_m=float(beta[VISCOUS]),
        interval_n_s_m=(float(np.percentile(boot, 2.5)), float(np.percentile(boot, 97.5))),
        band_low_n_s_m=low,
        below_share=float(np.mean(boot < low)),
        rms_n=rms,
        samples=total,
    )


def _num(v: float) -> float | None:
    return round(float(v), 1) if np.isfinite(v) else None


def _unread(low: float, why: str, rms: float = np.inf, samples: int = 0) -> ThinOil:
    return ThinOil(np.nan, (np.nan, np.nan), low, 0.0, rms, samples, why)
