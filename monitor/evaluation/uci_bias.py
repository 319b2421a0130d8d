"""The rig's bias statistic B beside J (``monitor eval-uci``): each output's mean residual over
each load phase of the cycle, over its largest held-out healthy value.

J squares each second's residual and keeps the largest window of N + 1 s, so a small offset
that lasts a whole load phase (a softer accumulator shifts the pressures a little for as long
as the load holds) adds little to it.  The machine's B (``monitor.model.bias``) averages the
residual by operating regime; the rig records no command, and its regime is the phase of its
fixed 60 s load schedule.  Per cycle and output k, over phases of ``phase_s`` seconds:

    m[s, k]     = mean residual of output k over phase s (the unpredicted first seconds and
                  any NaN left out; NaN when the phase has none)
    scale[s, k] = largest |m[s, k]| over the held-out healthy cycles
    B           = max over s, k of |m[s, k]| / scale[s, k]  (entries without a scale skipped)

The cycle alarms when its largest J exceeds eps0 or B exceeds b0, b0 the threshold rule on
the held-out cycles' B (twice the largest, 2, by default).  The phase length is chosen on
--train alone, with N and the preset; "none" (J alone) competes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.model.threshold import ThresholdRule

#: Phase lengths tried (s): the rig's load schedule changes about every 10 s.
PHASES_S = (10, 20, 60)


def phase_means(e: np.ndarray, phase_s: int) -> np.ndarray:
    """(cycles, seconds, outputs) residuals -> (cycles, phases, outputs) means; the seconds
    beyond the last whole phase are left out."""
    n, t, k = e.shape
    whole = t - t % phase_s
    seg = e[:, :whole].reshape(n, whole // phase_s, phase_s, k)
    counts = np.isfinite(seg).sum(axis=2)
    sums = np.nansum(seg, axis=2)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, sums / counts, np.nan)


def phase_scale(means: np.ndarray) -> np.ndarray:
    """(phases, outputs): the largest |mean| over the given cycles; NaN where it is not
    positive (a phase never predicted, or always exact): such an entry is never judged."""
    if not means.shape[0]:
        return np.full(means.shape[1:], np.nan)
    with np.errstate(invalid="ignore"):
        top = np.nanmax(np.abs(means), axis=0)
    return np.where(top > 0, top, np.nan)


def _ratios(means: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """|m| / scale per cycle, phase and output; 0 where not judged (no scale, no mean)."""
    with np.errstate(invalid="ignore"):
        ratio = np.abs(means) / scale
    return np.where(np.isfinite(ratio), ratio, 0.0)


def cycle_b(means: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """B of each cycle (cycles,); 0 for a cycle with no judged entry."""
    ratio = _ratios(means, scale)
    return ratio.max(axis=(1, 2)) if ratio.size else np.zeros(means.shape[0])


@dataclass(frozen=True)
class CycleRule:
    """What a cycle is judged by: eps0 of its largest J, and B's scales and b0 (None: J
    alone)."""

    eps0: float
    scale: np.ndarray | None = None
    b0: float = float("nan")

    @classmethod
    def fit(
        cls, jmax: np.ndarray, means: np.ndarray | None, idx: np.ndarray, rule: ThresholdRule
    ) -> CycleRule:
        """Thresholds from the healthy cycles ``idx``."""
        _, eps0 = rule.eps0(jmax[idx])
        if means is None:
            return cls(eps0)
        scale = phase_scale(means[idx])
        _, b0 = rule.eps0(cycle_b(means[idx], scale))
        return cls(eps0, scale, b0)

    def first_b_alarm_s(self, means: np.ndarray, phase_s: int) -> np.ndarray:
        """Per cycle: the last second of the first phase whose B exceeds b0 (NaN: none)."""
        if self.scale is None:  # J alone: B raises no alarm
            return np.full(means.shape[0], np.nan)
        above = np.any(_ratios(means, self.scale) > self.b0, axis=2)
        first = np.argmax(above, axis=1)
        return np.where(np.any(above, axis=1), (first + 1) * phase_s - 1.0, np.nan)

    def alarms(self, jmax: np.ndarray, means: np.ndarray | None) -> np.ndarray:
        """Per cycle: largest J above eps0, or B above b0."""
        out = jmax > self.eps0
        if self.scale is not None and means is not None:
            out = out | (cycle_b(means, self.scale) > self.b0)
        return out
