"""Alarm state machine with debounce, and the running fault isolation it reports.

States follow the DBC's value table of MON_Alarm.State.  One ``AlarmMachine.step`` per
100 Hz sample, whether the sample came from a file or from the bus, so a recording gives the
same events at a desk as on the machine.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from monitor.errors import ConfigError


class State(IntEnum):
    NORMAL = 0
    FAULT = 1
    SENSOR_FAULT = 2
    INACTIVE = 3

    @property
    def label(self) -> str:
        return self.name.lower()


@dataclass(frozen=True)
class AlarmConfig:
    """Debounce (in 100 Hz samples) and gating of the alarm state machine."""

    raise_samples: int = 50  # J above eps0 this long raises a fault (0.5 s)
    clear_samples: int = 300  # J below clear_ratio * eps0 this long clears it (3 s)
    clear_ratio: float = 0.8  # hysteresis: a fault clears only well below the threshold
    sensor_recover_samples: int = 10  # valid data this long ends a sensor fault (0.1 s)
    min_engine_rpm: float = 500.0  # below: the machine is off, the monitor inactive
    # An alarm episode outlives an inactive or sensor-fault gap up to this long (60 s): the
    # fault comes back as the same episode (same isolation, no new black box or DM1
    # occurrence) and ends only by the clear rule.  A longer gap ends the episode.
    episode_gap_samples: int = 6000

    def __post_init__(self) -> None:
        for name in (
            "raise_samples",
            "clear_samples",
            "sensor_recover_samples",
            "episode_gap_samples",
        ):
            if int(getattr(self, name)) < 1:
                raise ConfigError(f"alarm.{name} must be at least 1 sample")
        if not 0.0 < self.clear_ratio <= 1.0:
            raise ConfigError(f"alarm.clear_ratio must be in (0, 1], got {self.clear_ratio}")
        if self.min_engine_rpm < 0:
            raise ConfigError("alarm.min_engine_rpm must be >= 0")


#: Spool command (%) beyond which the loop counts as raising / lowering for isolation.
REGIME_SPOOL_PCT = 5.0
N_REGIMES = 3  # hold, raise, lower


def regime_of(spool_pct: float) -> int:
    if spool_pct > REGIME_SPOOL_PCT:
        return 1
    if spool_pct < -REGIME_SPOOL_PCT:
        return 2
    return 0


def regimes_of(spool_pct: np.ndarray) -> np.ndarray:
    """``regime_of`` for a whole series (NaN counts as hold, as there)."""
    s = np.asarray(spool_pct, dtype=np.float64)
    return np.where(s > REGIME_SPOOL_PCT, 1, np.where(s < -REGIME_SPOOL_PCT, 2, 0))


class Isolator:
    """Names the likely fault from the mean signed residual per output and spool regime.

    The signature of a fault is the direction of that vector (cosine similarity), not its
    length, so one centroid per fault serves every severity.  Regimes not yet seen in the
    alarm are left out of the comparison.
    """

    def __init__(
        self,
        labels: tuple[str, ...],
        centroids: np.ndarray,
        n_outputs: int,
        min_similarity: float = 0.5,
    ) -> None:
        self.labels = labels
        self.centroids = np.asarray(centroids, dtype=np.float64)
        self.n_outputs = n_outputs
        self.min_similarity = min_similarity
        self.sums = np.zeros((N_REGIMES, n_outputs))
        self.counts = np.zeros(N_REGIMES)

    def reset(self) -> None:
        self.sums[:] = 0.0
        self.counts[:] = 0.0

    def add(self, e: np.ndarray, regime: int) -> None:
        if np.all(np.isfinite(e)):
            self.sums[regime] += e
            self.counts[regime] += 1.0

    def add_many(self, e: np.ndarray, regimes: np.ndarray) -> None:
        """``add`` for each row of ``e`` in order (the same sums to the bit: ``np.add.at``
        adds row by row), without a Python loop: a raise seeds N rows at once."""
        ok = np.isfinite(e).all(axis=1)
        r = regimes[ok]
        np.add.at(self.sums, r, e[ok])
        self.counts += np.bincount(r, minlength=len(self.counts))

    def signature(self) -> np.ndarray:
        """Mean residual per regime and output, flattened; NaN for unseen regimes."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return (self.sums / self.counts[:, None]).ravel()

    def label(self) -> str:
        return classify(self.signature(), self.labels, self.centroids, self.min_similarity)


def classify(
    sig: np.ndarray, labels: tuple[str, ...], centroids: np.ndarray, min_similarity: float
) -> str:
    if not labels:
        return "unknown"
    seen = np.isfinite(sig)
    if not seen.any():
        return "unknown"
    s = sig[seen]
    best, best_sim = "unknown", -np.inf
    for label, c in zip(labels, centroids, strict=True):
        cc = c[seen]
        denom = np.linalg.norm(s) * np.linalg.norm(cc)
        sim = float(s @ cc / denom) if denom > 0 else -np.inf
        if sim > best_sim:
            best, best_sim = label, sim
    return best if best_sim >= min_similarity else "unknown"


class SeedRing:
    """The last N residual rows and their spool regimes, oldest overwritten first: what
    seeds the isolation when the debounce raises an alarm."""

    def __init__(self, window_n: int, n_outputs: int) -> None:
        self.e = np.full((max(window_n, 1), n_outputs), np.nan)
        self.regime = np.zeros(max(window_n, 1), dtype=np.int64)
        self.pos = 0

    def push(self, e: np.ndarray, regime: int) -> None:
        self.e[self.pos] = e
        self.regime[self.pos] = regime
        self.pos = (self.pos + 1) % self.e.shape[0]

    def push_many(self, e: np.ndarray, regimes: np.ndarray) -> None:
        """``push`` for each row in order; only the last N rows can stay."""
        n = len(regimes)
        if n == 0:
            return
        size = self.e.shape[0]
        take = min(n, size)  # earlier samples of the run would be overwritten anyway
        idx = (self.pos + n - take + np.arange(take)) % size
        self.e[idx] = e[n - take :]
        self.regime[idx] = regimes[n - take :]
        self.pos = (self.pos + n) % size

    def clear(self) -> None:
        self.e[:] = np.nan


class AlarmMachine:
    """Per-sample state: inactive > sensor fault > fault/normal, with debounce.

    Episodes: a fault raised by the debounce opens an alarm episode (``raised`` is True on
    that sample only); the clear rule closes it.  While it is open, an inactive or
    sensor-fault gap of at most ``episode_gap_samples`` shows as such, and when valid data
    returns the state goes straight back to fault with the isolation it had: one fault, one
    episode, one black box, one DM1 occurrence.  A longer gap closes the episode.
    """

    def __init__(
        self, config: AlarmConfig, eps0: float, isolator: Isolator | None = None, window_n: int = 0
    ) -> None:
        self.config = config
        self.eps0 = float(eps0)
        self.isolator = isolator
        self.window_n = window_n
        self.state = State.NORMAL
        self.fault = "none"
        self.episode_open = False  # a raised fault the clear rule has not ended
        self.raised = False  # the last step opened a new episode
        self._gap = 0  # samples the open episode has spent outside the fault state
        self._episode_fault = "none"  # its isolation when it left the fault state
        self._above = 0
        self._below = 0
        self._valid = 0
        self._named = ""  # the fault the statistic setting the level names ("": none)
        # The last N residuals (and regimes) seed the isolation when an alarm is raised:
        # the samples that pushed J over the threshold.
        n_out = isolator.n_outputs if isolator is not None else 0
        self._seed = SeedRing(window_n, n_out)

    def step(
        self,
        j: float,
        inputs_ok: bool,
        engine_rpm: float,
        e: np.ndarray | None = None,
        regime: int = 0,
        operating: bool = True,
        running: bool = False,
        named: str = "",
    ) -> State:
        """``operating`` False: the machine runs outside normal operation (warm-up, see
        ``monitor.detection.opstate``) and the monitor is inactive as with the engine off.
        ``running``: the engine runs whatever ``engine_rpm`` says (it is missing while the
        pump shows a working machine: ``opstate.silent_source``).  ``named``: the fault the
        statistic setting ``j`` names (``Statistic.names``; "": the isolator names it)."""
        cfg = self.config
        self.raised = False
        self._named = named
        # NaN engine speed: off, unless ``running``
        if not ((running or engine_rpm >= cfg.min_engine_rpm) and operating):
            self._in_gap()
            return self._enter(State.INACTIVE)
        if not inputs_ok:
            self._valid = 0
            self._in_gap()
            return self._enter(State.SENSOR_FAULT)
        if self.state in (State.INACTIVE, State.SENSOR_FAULT):
            self._valid += 1
            if self.state is State.SENSOR_FAULT and self._valid < cfg.sensor_recover_samples:
                self._in_gap()
                return self.state
            if self.episode_open:
                self._resume()
            else:
                self._enter(State.NORMAL)
        if e is not None and self.isolator is not None:
            self._seed.push(e, regime)
        if j != j:  # NaN: the window is warming up or paused; the debounce counts pause too
            if self.state is State.FAULT and self.isolator is not None and e is not None:
                self.isolator.add(e, regime)
            return self.state
        above = j > self.eps0
        if self.state is State.NORMAL:
            self._above = self._above + 1 if above else 0
            if self._above >= cfg.raise_samples:
                self._enter(State.FAULT)
        else:
            if self.isolator is not None and e is not None:
                self.isolator.add(e, regime)
                self.fault = self.isolator.label()
            if named:
                self.fault = named
            self._below = self._below + 1 if j < cfg.clear_ratio * self.eps0 else 0
            if self._below >= cfg.clear_samples:
                self.episode_open = False
                self._enter(State.NORMAL)
        return self.state

    def carry_over(self, old: AlarmMachine) -> None:
        """A reload: the alarm state, its isolation and its episode go on in this machine
        (its debounce counts start again: they counted the old model's J)."""
        self.state, self.fault = old.state, old.fault
        self.episode_open, self._gap = old.episode_open, old._gap
        self._episode_fault, self._valid = old._episode_fault, old._valid

    def _in_gap(self) -> None:
        """One sample of an open episode outside the fault state; too many close it."""
        if self.episode_open:
            self._gap += 1
            if self._gap > self.config.episode_gap_samples:
                self.episode_open = False

    def _resume(self) -> None:
        """Valid data again within the open episode: fault, as before the gap."""
        self._above = self._below = 0
        self._gap = 0
        self.state = State.FAULT
        self.fault = self._episode_fault

    def skip_quiet(self, e: np.ndarray, regimes: np.ndarray) -> None:
        """``step`` over a run of quiet samples in ``NORMAL`` at once: engine on, inputs
        complete, J finite and <= eps0.  There ``step`` only resets the raise debounce and
        remembers each residual (rows of ``e``) and regime for isolation, so only the last
        N of them matter.  ``monitor detect`` spends most of a recording in such runs."""
        if self.state is not State.NORMAL:
            raise ValueError("skip_quiet is only for runs in the NORMAL state")
        self._above = 0
        if self.isolator is not None:
            self._seed.push_many(e, regimes)

    def _enter(self, state: State) -> State:
        if state is not self.state:
            self._above = self._below = 0
            if self.state is State.FAULT:
                self._episode_fault = self.fault  # kept for a return within the episode
            if state is State.FAULT:  # raised by the debounce: a new episode
                self.raised = True
                self.episode_open = True
                self._gap = 0
                self.fault = "unknown"
                if self.isolator is not None:
                    self.isolator.reset()
                    self.isolator.add_many(self._seed.e, self._seed.regime)
                    self.fault = self.isolator.label()
                if self._named:
                    self.fault = self._named
            else:
                self.fault = "none"
            if state is not State.NORMAL:
                self._seed.clear()
            self.state = state
        return self.state
