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

The OilTemp these rules see is the one believed under a rate-of-change limit, and a change
of the state reported needs the evidence of more than one frame
(``monitor.detection.evidence``).

A missing EngineSpeed is not always an engine off: when the message that carries it
(HYD_Commands) falls silent, or its frames are rejected, while the pump shows a working
machine, the source is silent, not the machine (``silent_source``).  The finding starts once
EngineSpeed has been missing for ``operating.silent_settle_s`` with PP fresh above
``plausibility.rest_max_bar`` throughout (the reading the rest check allows for a stopped pump
bled to tank) and QP fresh at ``plausibility.move_flow_lpm`` or more (the flow that counts as
moving: the pump turns); it holds while EngineSpeed stays missing and PP fresh above
``rest_max_bar``, so a boom held at pressure (no flow) does not flap it.  While it holds, the
engine counts as running (``op_states`` and the tracker then decide warm-up or normal from
OilTemp) and the sample is a sensor fault naming EngineSpeed, check ``stale``
(``monitor.detection.gating``).  A silence in which the pump never delivers flow after the
settle time, in which PP goes stale too (the whole bus silent, as at key-off) or bleeds to
tank, stays ``engine_off``.

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
    # Long enough that the whole bus going quiet at key-off is not taken for it: messages
    # stop a cycle or so apart, and the pump stops delivering as the engine spins down.
    silent_settle_s: float = 1.0  # EngineSpeed missing this long, pump working: sensor fault
    # One frame is not evidence (``monitor.detection.evidence``); 0 switches each off.
    oil_rate_max_c_per_s: float = 2.0  # OilTemp moving faster is not believed (one frame)
    engine_confirm_s: float = 0.05  # engine start/stop reported after this (EngineSpeed 10 ms)
    oil_confirm_s: float = 1.5  # warm-up start/end after this (OilTemp once a second)

    def __post_init__(self) -> None:
        if not -40.0 <= self.warmup_oil_c <= 150.0:
            raise ConfigError(
                f"operating.warmup_oil_c must be within -40..150 degC, got {self.warmup_oil_c}"
            )
        if self.warmup_hysteresis_c < 0:
            raise ConfigError("operating.warmup_hysteresis_c must be >= 0")
        if not 0.0 <= self.silent_settle_s <= 60.0:
            raise ConfigError(
                f"operating.silent_settle_s must be within 0..60 s, got {self.silent_settle_s}"
            )
        if not self.oil_rate_max_c_per_s >= 0:
            raise ConfigError(
                f"operating.oil_rate_max_c_per_s must be >= 0 (0: off), got "
                f"{self.oil_rate_max_c_per_s}"
            )
        for name in ("engine_confirm_s", "oil_confirm_s"):
            if not 0.0 <= getattr(self, name) <= 60.0:
                raise ConfigError(
                    f"operating.{name} must be within 0..60 s, got {getattr(self, name)}"
                )


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


def silent_source(
    engine_rpm: np.ndarray,
    pp_bar: np.ndarray,
    qp_lpm: np.ndarray,
    rest_bar: float,
    flow_lpm: float,
    settle_n: int,
) -> np.ndarray:
    """Per sample (bool): EngineSpeed missing while the pump shows a working machine (module
    docstring); the same decisions as ``SilenceTracker`` sample by sample."""
    engine = np.asarray(engine_rpm, dtype=np.float64)
    pp = np.asarray(pp_bar, dtype=np.float64)
    qp = np.asarray(qp_lpm, dtype=np.float64)
    idx = np.arange(len(engine))
    with np.errstate(invalid="ignore"):
        hold = np.isnan(engine) & (pp > rest_bar)  # NaN PP compares False: not held
        flow = qp >= flow_lpm
    # Samples since the last one outside ``hold`` (the run of it so far, this one included).
    last_out = np.maximum.accumulate(np.where(hold, -1, idx)) if len(idx) else idx
    start = hold & flow & (idx - last_out > settle_n)
    # Held from a start to the end of its run of ``hold``.
    last_start = np.maximum.accumulate(np.where(start, idx, -1)) if len(idx) else idx
    return hold & (last_start > last_out)


class SilenceTracker:
    """``silent_source`` one sample at a time (the live path)."""

    def __init__(self, rest_bar: float, flow_lpm: float, settle_n: int) -> None:
        self.rest_bar = float(rest_bar)
        self.flow_lpm = float(flow_lpm)
        self.settle_n = int(settle_n)
        self.run = 0  # samples of ``hold`` in a row
        self.silent = False

    def step(self, engine_rpm: float, pp_bar: float, qp_lpm: float) -> bool:
        hold = engine_rpm != engine_rpm and pp_bar > self.rest_bar
        self.run = self.run + 1 if hold else 0
        start = self.run > self.settle_n and qp_lpm >= self.flow_lpm
        self.silent = hold and (self.silent or start)
        return self.silent


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
