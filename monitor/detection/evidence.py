"""The evidence an operating-state change needs: within what CAN allows, one frame is not
enough (a forged frame passes CRC-8 about once in 256 tries and its counter may be right).

* Rate of change: oil temperature moves slowly (a tank of oil warms by degrees per minute;
  it cannot move 40 degC in 10 ms).  A reading further from the last believed one than
  ``operating.oil_rate_max_c_per_s`` times the time since then (and never less than one
  second's worth: the message comes once a second) is not believed; the last believed
  reading stands in for it.  A reading away from it for ``operating.oil_confirm_s`` in a row
  (longer than one HYD_OilTemp period: more than one frame) is believed after all, so a
  sensor that really jumped, or data from another machine, is followed.
* Confirmation: the operating state reported (and acted on: the alarm goes inactive only in
  a reported engine-off or warm-up) changes only after the state computed from the
  readings has differed from it for ``operating.engine_confirm_s`` in a row (an engine start
  or stop, from EngineSpeed every 10 ms: several frames) or ``operating.oil_confirm_s``
  (warm-up begins or ends, from OilTemp once a second: more than one frame).  A change while
  EngineSpeed is missing is no frame's word and needs none: unknown counts as off at once, as
  it always has (the whole bus quiet at key-off), and a silent source found after its own
  settle time (``opstate.silent_source``) counts at once.  Samples whose computed state is
  not normal are still not judged (``Gate.gated``): confirmation delays what is reported,
  never what is judged.

Both have a per-sample class (the daemon's tick) and a whole-recording function (``monitor
detect``) that give the same values sample by sample; the recording functions step over
runs of equal values, so an hour of 100 Hz rows costs a loop over its changes.
"""

from __future__ import annotations

import math

import numpy as np

from monitor.detection.opstate import OpState
from monitor.signals import SAMPLE_PERIOD_S


class OilBelief:
    """``believed_oil`` one sample at a time (the live path)."""

    def __init__(self, rate_c_per_s: float, confirm_n: int) -> None:
        self.rate = float(rate_c_per_s)
        self.confirm_n = int(confirm_n)
        self.value = math.nan  # the last believed reading (NaN: none yet)
        self.age_n = 0  # samples since it was read
        self.doubt_n = 0  # readings in a row not believed

    def step(self, oil_c: float) -> float:
        self.age_n += 1
        if oil_c != oil_c:  # missing: no evidence either way
            return self.value
        allowed = self.rate * max(self.age_n * SAMPLE_PERIOD_S, 1.0)
        if (
            self.value != self.value
            or self.rate <= 0
            or abs(oil_c - self.value) <= allowed
            or self.doubt_n + 1 >= self.confirm_n
        ):
            self.value, self.age_n, self.doubt_n = oil_c, 0, 0
        else:
            self.doubt_n += 1
        return self.value


def believed_oil(oil_c: np.ndarray, rate_c_per_s: float, confirm_n: int) -> np.ndarray:
    """Per sample the oil temperature believed (module docstring), NaN before the first
    reading; the same values as stepping ``OilBelief``."""
    oil = np.asarray(oil_c, dtype=np.float64)
    n = len(oil)
    out = np.full(n, np.nan)
    if n == 0:
        return out
    b = OilBelief(rate_c_per_s, confirm_n)
    # Runs of equal readings (NaN runs included): within a run the state evolves without
    # surprise, so only the first samples of a run need the rule.
    same = (oil[1:] == oil[:-1]) | (np.isnan(oil[1:]) & np.isnan(oil[:-1]))
    starts = np.concatenate([[0], np.flatnonzero(~same) + 1, [n]])
    for a, z in zip(starts[:-1], starts[1:], strict=True):
        i = a
        # Step until the run's reading is believed (or is missing), then fill the rest.
        while i < z:
            out[i] = b.step(oil[i])
            i += 1
            if oil[a] != oil[a] or b.value == oil[a]:
                break
        if i < z:
            out[i:z] = b.value
            b.age_n = b.age_n + (z - i) if oil[a] != oil[a] else 0
    return out


def _confirm_n(a: int, b: int, engine_n: int, oil_n: int) -> int:
    """Samples a change from state ``a`` to ``b`` needs (at least the one that shows it)."""
    return max(1, engine_n if OpState.ENGINE_OFF in (a, b) else oil_n)


class StateConfirmer:
    """``confirmed_states`` one sample at a time (the live path)."""

    def __init__(self, engine_n: int, oil_n: int) -> None:
        self.engine_n, self.oil_n = int(engine_n), int(oil_n)
        self.state: int | None = None  # the reported state (None before the first sample)
        self.candidate = -1
        self.run = 0

    def step(self, computed: int, engine_missing: bool = False) -> int:
        if self.state is None or computed == self.state or engine_missing:
            self.state = computed
            self.run = 0
            return self.state
        self.run = self.run + 1 if computed == self.candidate else 1
        self.candidate = computed
        if self.run >= _confirm_n(self.state, computed, self.engine_n, self.oil_n):
            self.state, self.run = computed, 0
        return self.state


def confirmed_states(
    computed: np.ndarray, engine_missing: np.ndarray, engine_n: int, oil_n: int
) -> np.ndarray:
    """The reported operating state per sample (int8): the first sample's computed state,
    then a change only after the computed state has held it for the confirmation samples,
    or at once where EngineSpeed is missing (module docstring); the same values as stepping
    ``StateConfirmer``."""
    computed = np.asarray(computed, dtype=np.int8)
    n = len(computed)
    out = np.empty(n, dtype=np.int8)
    if n == 0:
        return out
    starts = np.concatenate([[0], np.flatnonzero(np.diff(computed)) + 1, [n]])
    missing = np.flatnonzero(engine_missing)
    state = int(computed[0])
    for a, z in zip(starts[:-1], starts[1:], strict=True):
        s = int(computed[a])
        # The run confirms the change at its need-th sample, or at its first sample with
        # EngineSpeed missing.
        at = a + _confirm_n(state, s, engine_n, oil_n) - 1
        k = int(np.searchsorted(missing, a))
        if k < len(missing):
            at = min(at, int(missing[k]))
        if s == state or at >= z:
            out[a:z] = state
            continue
        out[a:at] = state
        state = s
        out[at:z] = state
    return out
