"""F's own oil range: how far beyond the oil commissioning reached the flow-continuity
statistic may judge, from what commissioning itself shows of its feature's oil dependence.

The model's envelope leaves out samples whose oil lies beyond the trained range plus its
margin: the DGRNN cannot extrapolate in oil temperature.  F's feature, the pump's flow less
the rod side's area times the lowering speed (``monitor.model.flow``), is continuity: it
moves with the oil only through the leakage past the seals and the spool, which thinner oil
raises.  Commissioning shows how much: the run warms its oil through some 10-15 degC, so
the feature regressed on the oil over its lowerings gives a slope (L/min per degC) and that
slope's standard error.

One point per lowering (counted samples closer than ``GROUP_GAP_N`` together; its mean oil
and mean excess): the samples of one lowering share their oil and most of their scatter, so
the lowerings, not the samples, are the independent observations.  The excess a window of
F averages would shift at an oil T by the slope times (T - the lowerings' mean oil); F
judges a sample beyond the envelope where that shift upwards, with the slope taken ``OIL_Z``
standard errors steeper, stays within ``OIL_SHARE`` of the threshold (f0 x the scale, in
L/min), and no further from the oil commissioning's lowerings saw than their own span (a
line is not extrapolated beyond the length it was fitted on).  F is one-sided (the positive
part of the mean excess), so only a rise can raise a false alarm; a fall lowers F and hides
a leak of that size, which the support line states as the slope's shift at the range's end.
Fewer than three lowerings, or no spread in their oil, give no slope: F then judges only the
oil its lowerings saw.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from monitor.io.recording import Recording

#: Share of F's threshold (in L/min) the extrapolated oil shift may take: a normal window
#: shifted so still needs three quarters of the threshold from its own scatter to alarm.
OIL_SHARE = 0.25
#: Standard errors the slope is taken steeper by (two: some 97.5 % one-sided).
OIL_Z = 2.0
#: Counted samples further apart than this (1 s) belong to different lowerings.
GROUP_GAP_N = 100


@dataclass(frozen=True)
class OilTrend:
    """F's feature against the oil on commissioning's lowerings."""

    lowerings: int  # points the slope rests on
    mean_c: float  # their mean oil, degC
    lo_c: float  # the coldest and warmest oil of a counted sample, degC
    hi_c: float
    slope_lpm_per_c: float  # the excess's change per degC (NaN: none)
    se_lpm_per_c: float  # its standard error (NaN: none)

    def range_c(self, allowance_lpm: float) -> tuple[float, float]:
        """F's own oil range (degC) for an allowed upward shift of ``allowance_lpm``."""
        if not np.isfinite(self.se_lpm_per_c):
            return self.lo_c, self.hi_c
        span = self.hi_c - self.lo_c
        margin = OIL_Z * self.se_lpm_per_c
        warmer = _reach(allowance_lpm, self.slope_lpm_per_c + margin)
        colder = _reach(allowance_lpm, -self.slope_lpm_per_c + margin)
        return (
            float(max(self.mean_c - colder, self.lo_c - span)),
            float(min(self.mean_c + warmer, self.hi_c + span)),
        )

    def said(self, allowance_lpm: float, lo_c: float, hi_c: float) -> str:
        """F's oil range and what it rests on, for ``monitor train``'s support line."""
        judged = f"F's own oil range {lo_c:.1f}-{hi_c:.1f} degC (judged there beyond the envelope)"
        if not np.isfinite(self.se_lpm_per_c):
            return f"{judged}: the oil of its {self.lowerings} lowering(s), no slope"
        shift = self.slope_lpm_per_c * (hi_c - self.mean_c)
        return (
            f"{judged}: its excess moved {self.slope_lpm_per_c:+.4f} L/min per degC "
            f"(+-{self.se_lpm_per_c:.4f}, {self.lowerings} lowerings at "
            f"{self.lo_c:.1f}-{self.hi_c:.1f} degC, mean {self.mean_c:.1f}); there a rise at "
            f"{OIL_Z:g} standard errors stays within {OIL_SHARE:g} x f0 "
            f"({allowance_lpm:.3g} L/min), at most one span beyond that oil; at "
            f"{hi_c:.1f} degC the slope says {shift:+.3f} L/min"
            + (" (a fall hides a leak that size)" if shift < 0 else "")
        )


def _reach(allowance_lpm: float, rise_lpm_per_c: float) -> float:
    """How far (degC) the oil may go where the excess rises by ``rise_lpm_per_c`` per degC
    before it has risen by ``allowance_lpm`` (infinite where it does not rise: a lower
    excess can hide a leak, not raise a false alarm, and F is one-sided)."""
    return allowance_lpm / rise_lpm_per_c if rise_lpm_per_c > 0 else float(np.inf)


def oil_trend(
    recs: Sequence[Recording],
    feats: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]],
    a_lpm: float,
    b_lpm_per_mm_s: float,
) -> OilTrend:
    """The trend over the counted samples ``feats`` (per recording: counted 0/1, lowering
    speed mm/s, mean QP L/min) of the excess over the line ``a + b |v|``, one point per
    lowering; recordings without OilTemp give none."""
    oil: list[float] = []
    excess: list[float] = []
    seen: list[np.ndarray] = []
    for rec, (counted, speed, qmean) in zip(recs, feats, strict=True):
        if not rec.has("OilTemp"):
            continue
        idx = np.flatnonzero(counted == 1)
        temp = np.asarray(rec["OilTemp"], dtype=np.float64)
        for group in np.split(idx, np.flatnonzero(np.diff(idx) > GROUP_GAP_N) + 1):
            t = temp[group]
            t = t[np.isfinite(t)]
            if not t.size:
                continue
            seen.append(t)
            oil.append(float(t.mean()))
            excess.append(float(np.mean(qmean[group] - (a_lpm + b_lpm_per_mm_s * speed[group]))))
    if not seen:
        return OilTrend(0, np.nan, np.nan, np.nan, np.nan, np.nan)
    every = np.concatenate(seen)
    x, y = np.asarray(oil), np.asarray(excess)
    lo, hi, n = float(every.min()), float(every.max()), len(x)
    spread = float(np.sum((x - x.mean()) ** 2))
    if n < 3 or not spread > 0:
        return OilTrend(n, float(x.mean()), lo, hi, np.nan, np.nan)
    # Imported here: training only; scipy costs the daemon's start-up.
    from scipy.stats import linregress

    fit = linregress(x, y)  # least squares; stderr: the slope's standard error
    return OilTrend(n, float(x.mean()), lo, hi, float(fit.slope), float(fit.stderr))
