"""The alarm threshold eps0 = factor * J0 (eq. 10), with J0 taken from normal validation data.

The paper calls J0 "the sum of square residual under normal condition" without saying over
what.  Rules:

- ``max`` (default): J0 is the largest J seen on normal validation data.  With eps0 = 2 J0
  the monitor never alarms on data like its validation set, which is what a machine in the
  field needs (a false alarm a day ends trust in a monitor).
- ``quantile``: J0 is a high quantile (``quantile``, e.g. 0.999) of normal J: tighter, at the
  price of rare false alarms on transients the validation set barely covers.
- ``mean``: the literal reading, J0 = mean of normal J.  Ordinary duty-cycle transients then
  exceed eps0 (DESIGN.md); kept for comparison with the paper.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monitor.errors import ConfigError, InputFileError

THRESHOLD_RULES = ("max", "quantile", "mean")


@dataclass(frozen=True)
class ThresholdRule:
    rule: str = "max"
    quantile: float = 0.999
    factor: float = 2.0

    def __post_init__(self) -> None:
        if self.rule not in THRESHOLD_RULES:
            raise ConfigError(f"threshold rule must be one of {THRESHOLD_RULES}, got {self.rule!r}")
        if not 0.5 <= self.quantile < 1.0:
            raise ConfigError(f"threshold quantile must be in 0.5..1, got {self.quantile}")
        if not self.factor > 0:
            raise ConfigError(f"threshold factor must be positive, got {self.factor}")

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

    def eps0(self, normal_j: np.ndarray) -> tuple[float, float]:
        """(J0, eps0 = factor * J0)."""
        j0 = self.j0(normal_j)
        return j0, self.factor * j0

    def to_dict(self) -> dict[str, object]:
        return {"rule": self.rule, "quantile": self.quantile, "factor": self.factor}
