"""Base mismatch: the part of the held-out gap that no catalogue effect's physics produces.

A real machine's base dynamics always differ from any simulator's: orifice laws near a
closed spool, line dynamics, the damping of the oil column's resonance.  For this boom the
resonance sits at f = sqrt(beta A^2 / (V m)) / (2 pi) = sqrt(1.5e9 * 3.1e-3^2 /
(0.6e-3 * 400)) / (2 pi), about 40 Hz (tens of Hz over the stroke and the tolerances), and
a base mismatch shows as ringing at 15-50 Hz and in the shape of the half second after a
command change.

The catalogue's effects act on what the duty cycle drives: leakage, friction, load and
gains change the slow balance of flows and forces; lags, compliance and pump or spool
dynamics change how the pressures follow the commands, which are rate-limited to 200 %/s
over phases of 1-4 s.  What an effect changes therefore shows below a few hertz, where
the commands have their power.  So the residual is split by a centred moving average of
``SMOOTH_S`` (first null at 1 / SMOOTH_S = 5 Hz, gain 0.8 at 1.7 Hz, 0.99 at 0.25 Hz).
A longer average (0.5 s, null at 2 Hz) was tried: it also took a periodic load at 1.7 Hz,
an out-of-catalogue disturbance, for base mismatch and called it ``none``.

- the *structured* gap: the smoothed residual's mean square above the smoothed noise
  (white noise through a W-sample average keeps 1/W of its variance);
- the *base mismatch*: the rest of the gap (ringing, the sharp part of transients), above
  the noise.

An effect is judged on the structured gap as well as the whole (``decide.py``), and
``none`` also covers a simulator whose structured residual is below a practical level on
every signal, when no effect explains it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.ndimage import uniform_filter1d

from monitor.gap.data.prepare import Prepared
from monitor.gap.data.segments import Segment
from monitor.gap.fit.score import SegmentSums, gap, segment_sums
from monitor.gap.judge.shrink import boot_mse
from monitor.signals import SAMPLE_RATE_HZ

#: Width of the moving average that keeps the structured part (s): first null at 5 Hz.
SMOOTH_S = 0.2
#: A structured residual below this share of the signal's standard deviation (NRMSE above
#: the noise), on every signal, does not change what the simulator is good for: 2 % of the
#: spread of a boom pressure (~50 bar) is 1 bar, the pressure sensors' own accuracy class.
PRACTICAL_NRMSE = 0.02


def width_samples() -> int:
    return max(int(round(SMOOTH_S * SAMPLE_RATE_HZ)), 1)


def smooth(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Moving average of ``v`` (NaN treated as 0) and the mask of its finite samples."""
    ok = np.isfinite(v)
    return uniform_filter1d(np.where(ok, v, 0.0), width_samples(), mode="nearest"), ok


def smoothed_sums(
    prep: Prepared, segments: Sequence[Segment], pred: dict[str, np.ndarray]
) -> SegmentSums:
    """Like ``score.segment_sums`` on the smoothed residual, segment by segment."""
    return segment_sums(prep, segments, pred, smooth)


def smoothed_floor(floor: np.ndarray) -> np.ndarray:
    """The noise floor after the moving average (white sensor noise: 1/W of it)."""
    return floor / width_samples()


def practically_small(smooth_nominal: SegmentSums, floor_s: np.ndarray) -> bool:
    """Every signal's structured residual (above the noise) below ``PRACTICAL_NRMSE``."""
    excess = np.maximum(smooth_nominal.mse() - floor_s, 0.0)
    return bool(np.all(np.sqrt(excess) < PRACTICAL_NRMSE))


def small_each(smooth_sums: SegmentSums, idx: np.ndarray, floor_s: np.ndarray) -> np.ndarray:
    """Per block-bootstrap resample (``idx``) of the held-out segments: every signal's
    structured residual is below ``PRACTICAL_NRMSE``."""
    excess = np.maximum(boot_mse(smooth_sums, idx) - floor_s, 0.0)
    return np.all(np.sqrt(excess) < PRACTICAL_NRMSE, axis=1)


def small_share(smooth_nominal: SegmentSums, idx: np.ndarray, floor_s: np.ndarray) -> float:
    """Share of block-bootstrap resamples (``idx``) of the held-out segments in which every
    signal's structured residual is below ``PRACTICAL_NRMSE``."""
    return float(np.mean(small_each(smooth_nominal, idx, floor_s)))


def removed_nrmse(
    smooth_nominal: SegmentSums, smooth_after: SegmentSums, floor_s: np.ndarray
) -> float:
    """The NRMSE of what an effect removes from the structured gap: the square root of the
    drop of the smoothed residual's excess over the noise, summed over the signals like the
    gap (the effect's own contribution, when it is what the simulator missed: r0 = e + b,
    r1 = b, |r0|^2 - |r1|^2 ~ |e|^2)."""
    ex0 = np.maximum(smooth_nominal.mse() - floor_s, 0.0).sum()
    ex1 = np.maximum(smooth_after.mse() - floor_s, 0.0).sum()
    return float(np.sqrt(max(ex0 - ex1, 0.0)))


def removes_practical(
    smooth_nominal: SegmentSums, smooth_after: SegmentSums, floor_s: np.ndarray
) -> bool:
    """What an effect removes reaches ``PRACTICAL_NRMSE``: the level below which a
    structured residual is ``none`` is also the least an effect must change to be named."""
    return removed_nrmse(smooth_nominal, smooth_after, floor_s) >= PRACTICAL_NRMSE


def _fast(whole: SegmentSums, smoothed: SegmentSums, floor: np.ndarray) -> np.ndarray:
    """Per signal: the gap the moving average removes (above the noise it removes)."""
    total = np.maximum(whole.mse() - floor, 0.0)
    return np.maximum(total - np.maximum(smoothed.mse() - smoothed_floor(floor), 0.0), 0.0)


def report(
    nominal: SegmentSums,
    smooth_nominal: SegmentSums,
    floor: np.ndarray,
    names: Sequence[str],
    after: tuple[SegmentSums, SegmentSums] | None = None,
) -> dict:
    """The JSON ``base_mismatch`` block (held out).

    ``share``: the part of the tolerance-calibrated simulator's gap that the moving average
    removes (ringing and transients' shape, above ``above_hz``: what no effect's physics
    produces) and that the verdict's effects (``after``: their whole and smoothed sums)
    leave; ``signals``: per signal, that part's NRMSE and share of the signal's own gap,
    and the calibrated simulator's structured NRMSE (what an effect could remove) against
    the practical level."""
    floor_s = smoothed_floor(floor)
    m, ms = nominal.mse(), smooth_nominal.mse()
    total = np.maximum(m - floor, 0.0)
    structured = np.maximum(ms - floor_s, 0.0)
    # An effect's own fast part (a deadband's sharper transients) is not base mismatch:
    # only what is still there with the effect added.
    base = np.minimum(_fast(nominal, smooth_nominal, floor), total)
    if after is not None:
        base = np.minimum(base, _fast(after[0], after[1], floor))
    g = gap(m, floor)
    signals: dict[str, dict[str, float]] = {}
    out = {
        "share": round(float(base.sum() / g), 4) if g > 0 else 0.0,
        "above_hz": round(1.0 / SMOOTH_S, 2),
        "practical_nrmse": PRACTICAL_NRMSE,
        "practically_small": practically_small(smooth_nominal, floor_s),
        "signals": signals,
    }
    for j, n in enumerate(names):
        signals[n] = {
            "share": round(float(base[j] / total[j]), 4) if total[j] > 0 else 0.0,
            "nrmse": round(float(np.sqrt(base[j])), 5),
            "structured_nrmse": round(float(np.sqrt(structured[j])), 5),
        }
    return out
