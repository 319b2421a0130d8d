"""Operating state of the machine: engine off, warm-up, normal.

The model is trained on a running, warm machine, so detection runs only in ``normal``:

* ``engine_off``: EngineSpeed below ``alarm.min_engine_rpm`` or missing (unknown counts as
  off, as the alarm machine has always done);
* ``warm_up``: the engine runs but OilTemp is below ``operating.warmup_oil_c``; it stays
  warm-up until OilTemp reaches that temperature and counts as cold again only below it
  minus ``operating.warmup_hysteresis_c`` (OilTemp comes at 1 Hz with 0.03 degC steps, and
  a reading at the line must not flap the state);
* ``normal``: otherwise.  A missing OilTemp keeps the last decision; before the first
  reading the machine counts as warm (no evidence of a cold start).

MON_Alarm.State shows both non-normal states as ``inactive`` (3); the operating state itself
goes into MON_Status.OpState (value table = ``OpState``) and the event log's ``op_state``.
The offline series and the per-tick tracker apply the same comparisons, so ``monitor
detect`` and the daemon agree sample by sample.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from monitor.errors import ConfigError


class OpState(IntEnum):
    NORMAL = 0
    WARM_UP = 1
    ENGINE_OFF = 2

    @property
    def label(self) -> str:
        return self.name.lower()


@dataclass(frozen=True)
class OperatingConfig:
    """``operating:`` section: when the machine counts as warm (degC)."""

    warmup_oil_c: float = 30.0  # below: warm-up, monitor inactive (state 3)
    warmup_hysteresis_c: float = 2.0  # cold again only below warmup_oil_c minus this

    def __post_init__(self) -> None:
        if not -40.0 <= self.warmup_oil_c <= 150.0:
            raise ConfigError(f"operating.warmup_oil_c must be within -40..150 degC, got "
                              f"{self.warmup_oil_c}")  # fmt: skip
        if self.warmup_hysteresis_c < 0:
            raise ConfigError("operating.warmup_hysteresis_c must be >= 0")


def op_states(
    engine_rpm: np.ndarray, oil_c: np.ndarray, min_engine_rpm: float, cfg: OperatingConfig
) -> np.ndarray:
    """``OpState`` per sample (int8) of a whole recording, starting warm."""
    oil = np.asarray(oil_c, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        hot = oil >= cfg.warmup_oil_c
        cold = oil < cfg.warmup_oil_c - cfg.warmup_hysteresis_c
        running = np.asarray(engine_rpm, dtype=np.float64) >= min_engine_rpm
    # Hysteresis: the last decisive reading (hot or cold) holds until the next one.
    last = np.where(hot | cold, np.arange(len(oil)), -1)
    np.maximum.accumulate(last, out=last)
    warm = np.where(last >= 0, hot[np.maximum(last, 0)], True)
    states = np.where(warm, OpState.NORMAL, OpState.WARM_UP).astype(np.int8)
    states[~running] = OpState.ENGINE_OFF
    return states


class OpStateTracker:
    """``op_states`` one sample at a time (the live path); no allocation per step."""

    def __init__(self, min_engine_rpm: float, cfg: OperatingConfig) -> None:
        self.min_engine_rpm = float(min_engine_rpm)
        self.hot_c = float(cfg.warmup_oil_c)
        self.cold_c = float(cfg.warmup_oil_c - cfg.warmup_hysteresis_c)
        self.warm = True
        self.state = OpState.NORMAL

    def step(self, engine_rpm: float, oil_c: float) -> OpState:
        if oil_c >= self.hot_c:
            self.warm = True
        elif oil_c < self.cold_c:
            self.warm = False
        if not engine_rpm >= self.min_engine_rpm:
            self.state = OpState.ENGINE_OFF
        else:
            self.state = OpState.NORMAL if self.warm else OpState.WARM_UP
        return self.state
