"""The alarm threshold eps0 = factor * J0 (eq. 10), with J0 taken from normal validation data.

The paper calls J0 "the sum of square residual under normal condition" without saying over
what.  Rules:

- ``max`` (default): J0 is the largest J seen on normal validation data.  With eps0 = 2 J0
  the monitor never alarms on data like its validation set, which is what a machine in the
  field needs (a false alarm a day ends trust in a monitor).
- ``quantile``: J0 is a high quantile (``quantile``, e.g. 0.999) of normal J: tighter, at the
  price of rare false alarms on transients the validation set barely covers.
- ``mean``: the literal reading, J0 = mean of normal J.  Ordinary duty-cycle transients then
  exceed eps0 (docs/explanation/method.md); kept for comparison with the paper.
- ``evt``: a threshold with a stated false-alarm rate.  The held-out series is cut into
  blocks one window long (so neighbouring maxima are nearly independent), a Gumbel
  distribution is fitted to the block maxima (scipy, maximum likelihood), and eps0 is its
  return level for ``rate_per_h`` exceedances per hour of operation: "eps0 chosen for < 1
  false alarm per 1/rate_per_h hours at this duty cycle".  eps0 is never below the largest
  value seen; J0 is that largest value.  ``factor`` does not apply.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from monitor.errors import ConfigError, InputFileError

THRESHOLD_RULES = ("max", "quantile", "mean", "evt")
#: A threshold "rests on one event" when the largest J of one window-long block is at least
#: this many times every other block's outside its neighbours.  On 18 simulated machines
#: commissioned on 20 minutes the ratio was 1.0-2.0 for 13 and 3.5-15 for 5, whose eps0 was
#: then 2-25 x the others' (docs/benchmarks.md, "Commissioning cross-fitted, J alone").
ONE_EVENT_RATIO = 3.0
#: Fewer block maxima than this cannot support a fitted tail: ``evt`` says so.
MIN_BLOCKS = 8


@dataclass(frozen=True)
class ThresholdRule:
    rule: str = "max"
    quantile: float = 0.999
    factor: float = 2.0
    rate_per_h: float = 1e-3  # ``evt``: target false alarms per hour of operation

    def __post_init__(self) -> None:
        if self.rule not in THRESHOLD_RULES:
            raise ConfigError(f"threshold rule must be one of {THRESHOLD_RULES}, got {self.rule!r}")
        if not 0.5 <= self.quantile < 1.0:
            raise ConfigError(f"threshold quantile must be in 0.5..1, got {self.quantile}")
        if not self.factor > 0:
            raise ConfigError(f"threshold factor must be positive, got {self.factor}")
        if not 1e-7 <= self.rate_per_h <= 1.0:
            raise ConfigError(f"threshold rate_per_h must be in 1e-7..1, got {self.rate_per_h}")

    def j0(self, normal_j: np.ndarray) -> float:
        """J0 from the J values of normal validation data (NaN, i.e. warm-up, ignored)."""
        j = np.asarray(normal_j, dtype=np.float64)
        j = j[np.isfinite(j)]
        if j.size == 0:
            raise InputFileError("no valid J on the normal validation data (too short?)")
        if self.rule == "max":
            return float(j.max())
        if self.rule == "quantile":
            return float(np.quantile(j, self.quantile))
        return float(j.mean())

    def eps0(
        self, normal_j: np.ndarray, block: int = 1, period_s: float = 0.01
    ) -> tuple[float, float]:
        """(J0, eps0): eps0 = factor * J0, or for ``evt`` the return level of the block
        maxima (blocks of ``block`` samples of ``period_s``), see :meth:`fit_evt`."""
        if self.rule == "evt":
            fit = self.fit_evt(normal_j, block, period_s)
            return fit["max"], fit["level"]
        j0 = self.j0(normal_j)
        return j0, self.factor * j0

    def fit_evt(self, series: np.ndarray, block: int, period_s: float = 0.01) -> dict[str, float]:
        """Gumbel fit of the block maxima of a normal series (NaN ignored; a block counts
        when at least half of it is finite): location, scale, the return level for
        ``rate_per_h`` and how many blocks it rests on."""
        from scipy.stats import gumbel_r

        maxima = [float(v.max()) for _, v in _blocks(series, block) if v.size * 2 >= block]
        if len(maxima) < MIN_BLOCKS:
            raise InputFileError(
                f"the evt threshold needs at least {MIN_BLOCKS} held-out windows of "
                f"{block * period_s:g} s, got {len(maxima)} (give more normal data, or use "
                "the max rule)"
            )
        loc, scale = gumbel_r.fit(maxima)
        p = self.rate_per_h * block * period_s / 3600.0  # exceedance probability per block
        level = float(gumbel_r.ppf(1.0 - p, loc, scale))
        top = max(maxima)
        return {
            "loc": float(loc),
            "scale": float(scale),
            "blocks": float(len(maxima)),
            "block_s": block * period_s,
            "max": top,
            "level": max(level, top),
        }

    def describe(self) -> str:
        """The rule in one line, for the model file and ``monitor train``."""
        if self.rule == "evt":
            return (
                f"chosen for < 1 false alarm per {1.0 / self.rate_per_h:g} h at the "
                "held-out data's duty cycle (Gumbel fit of per-window maxima)"
            )
        if self.rule == "quantile":
            return f"{self.factor:g} x the {self.quantile:g} quantile of held-out normal values"
        return f"{self.factor:g} x the {self.rule} of held-out normal values"

    def to_dict(self) -> dict[str, object]:
        return {
            "rule": self.rule,
            "quantile": self.quantile,
            "factor": self.factor,
            "rate_per_h": self.rate_per_h,
        }


def _blocks(series: np.ndarray, block: int, partial: bool = False):  # noqa: ANN202
    """(block number, its finite values) for each block of ``block`` samples; the last,
    shorter block too when ``partial``."""
    x = np.asarray(series, dtype=np.float64)
    n = len(x) // block + (partial and len(x) % block > 0)
    for k in range(n):
        part = x[k * block : (k + 1) * block]
        yield k, part[np.isfinite(part)]


def one_event(parts: Sequence[np.ndarray], block: int) -> dict[str, float] | None:
    """Where J0 comes from one event: the part (index), the first sample of its block, its J
    and how many times it is every other block's largest outside the neighbouring blocks
    (a J window spans two blocks); None when no block stands out by ``ONE_EVENT_RATIO``.
    Such a threshold is that much less sensitive, unless the event is the machine's
    normal work: the engineer should know which minute it was."""
    blocks = [
        (i, k, float(v.max()))
        for i, x in enumerate(parts)  # (part, block, max J)
        for k, v in _blocks(x, block, partial=True)
        if v.size
    ]
    if len(blocks) < 3:
        return None
    top = max(blocks, key=lambda b: b[2])
    rest = [m for i, k, m in blocks if i != top[0] or abs(k - top[1]) > 1]
    if not rest or max(rest) <= 0 or top[2] < ONE_EVENT_RATIO * max(rest):
        return None
    return {"part": top[0], "start": top[1] * block, "j": top[2], "ratio": top[2] / max(rest)}
