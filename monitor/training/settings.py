"""What `monitor train` is told, grouped as its options are: the DGRNN to fit, how the
thresholds are set, which statistics watch beside J, and how faults are isolated.  Light to
import (no kernels), so the command line can show the defaults.  Each group checks its own
values when it is made."""

from __future__ import annotations

from dataclasses import dataclass, field

from monitor.errors import ConfigError
from monitor.model.spec import PRESETS, DGRNNSpec
from monitor.model.threshold import ThresholdRule


@dataclass(frozen=True)
class DGRNNSettings:
    """The model fitted: ``--preset``, ``--horizon``, ``--max-patterns``, ``--lend``."""

    preset: str = "default"
    horizon: int | None = None  # None: the preset's own
    max_patterns: int = 6000  # smaller clusters: less bias where PP is steep in SpoolCmd
    exclude_neighbours: int = 50  # LOO leaves out +-0.5 s: 100 Hz rows are near copies
    #: With a reference model: lend its patterns where this machine's own data has none
    #: (``monitor.training.fill``), in the final model and in every cross-fitted fold.
    lend: bool = True
    #: The other loops' demand columns a ``section`` model reads (``--loop``).
    neighbours: tuple[str, ...] = ()
    #: A ``section`` model predicts the rod's speed from RodPos too (``--rod-speed``).
    rod_speed: bool = False

    def __post_init__(self) -> None:
        if self.preset not in PRESETS:
            raise ConfigError(f"unknown preset {self.preset!r}; known: {', '.join(PRESETS)}")

    def spec(self) -> DGRNNSpec:
        return DGRNNSpec.preset(self.preset, self.horizon, self.neighbours, self.rod_speed)


@dataclass(frozen=True)
class ThresholdSettings:
    """How the thresholds are set on normal data the GRNN never saw: ``--threshold-rule``
    (with ``--quantile``, ``--factor``, ``--rate``), ``--validation-fraction``, ``--folds``."""

    rule: ThresholdRule = field(default_factory=ThresholdRule)
    validation_fraction: float = 0.25
    #: Thresholds from residuals cross-fitted over all the normal data in this many folds
    #: (``monitor.training.crossfit``); 0: hold out the last ``validation_fraction``.  Off by
    #: default: on simulated 20-minute commissioning runs it found slight wear earlier but
    #: its bias statistic raised false alarms (docs/benchmarks.md, 2026-11-25).
    folds: int = 0
    fold_block_s: float = 60.0  # blocks dealt round-robin to the folds
    #: Bound |e| per output at this quantile of held-out normal |e| before J (None: eq. 9
    #: literal).  0.999 leaves sustained fault residuals alone and caps the rare one-sample
    #: events (end-stop impacts) that would otherwise set J0 by themselves.
    residual_clip_quantile: float | None = 0.999

    def __post_init__(self) -> None:
        if not 0.05 <= self.validation_fraction <= 0.5:
            raise ConfigError("validation fraction must be within 0.05..0.5")
        if self.folds != 0 and not 2 <= self.folds <= 20:
            raise ConfigError(f"folds must be 0 (hold out a share) or 2..20, got {self.folds}")
        if not 1.0 <= self.fold_block_s <= 3600.0:
            raise ConfigError(f"fold block must be within 1..3600 s, got {self.fold_block_s}")
        q = self.residual_clip_quantile
        if q is not None and not 0.9 <= q <= 1.0:
            raise ConfigError(f"residual clip quantile must be within 0.9..1, got {q}")

    @property
    def block_n(self) -> int:
        """A fold block in 100 Hz samples."""
        return int(round(self.fold_block_s * 100))


@dataclass(frozen=True)
class StatisticSettings:
    """The statistics that watch: J's window (``--window``), and beside J the bias
    statistic B (``--bias``), the full-lever statistic L (with B) and the hold statistic H
    (``--hold``, with B)."""

    window_n: int = 3000  # J window N (samples): 30 s spans several raise/hold/lower phases
    #: J leaves out the samples settling on an end stop (``--stops-in-j leave-out``): the
    #: stop carries the load and the chamber pressures settle by a path that depends on the
    #: payload and the pose; a model commissioned at one payload predicted it badly enough
    #: for 7 of 17 false alarms on the outsider's plant (docs/benchmarks.md, 2026-11-28,
    #: "J leaves out the rod settling on an end stop").
    j_leaves_out_stops: bool = True
    #: The bias statistic beside J (``monitor.model.bias``); None: on for every preset but
    #: ``paper``, which stays the paper's method (:attr:`TrainConfig.with_bias`).
    bias: bool | None = None
    bias_window_n: int = 6000  # 60 s: several raise/hold/lower phases of every regime
    bias_min_count: int = 300  # 3 s of a regime in the window before it counts
    #: The full-lever statistic L (``monitor.model.lever``), on with B, over B's window:
    #: 1 s of lever beyond full in one direction before that direction counts.
    lever_min_count: int = 100
    #: ... and on a section's flow (a shortfall only): 3 s, longer than a neighbour's pull
    #: of the shared pump into saturation (1-2 s).  At 1 s a normal bucket run of the whole
    #: machine's development 8 h reached 1.01 x l0, at 3 s the largest was 0.60 x
    #: (docs/benchmarks.md, "Stroke limits on the whole machine").
    flow_min_count: int = 300
    #: The hold statistic H (``monitor.model.hold``), over B's window and only with B: a
    #: hold's samples count once it has lasted 2 s (the move's pressure transients have died
    #: out), 3 s of such samples in the window before H is judged, holds on an end stop
    #: left out.  Off by default: its scales are the held-out data's largest values, and
    #: they were measured on hours of it (the shipped model's 10 h), not on minutes of
    #: commissioning (docs/benchmarks.md, 2026-11-27).
    hold: bool = False
    hold_settle_n: int = 200
    hold_min_count: int = 300
    #: Switch off an optional statistic its held-out data does not support
    #: (``monitor.training.support``); False keeps every one that could be fitted
    #: (``--support-check off``: experiments, tests of a statistic's own mechanics).
    support_check: bool = True

    def __post_init__(self) -> None:
        if self.window_n < 1:
            raise ConfigError(f"window N must be at least 1 sample, got {self.window_n}")
        if not 1 <= self.bias_min_count <= self.bias_window_n:
            raise ConfigError("bias min_count must be within 1..bias window")
        for count in (self.lever_min_count, self.flow_min_count):
            if not 1 <= count <= self.bias_window_n:
                raise ConfigError("lever min_count must be within 1..bias window")
        if not 1 <= self.hold_min_count <= self.bias_window_n or self.hold_settle_n < 0:
            raise ConfigError("hold min_count must be within 1..bias window, settle >= 0")


@dataclass(frozen=True)
class IsolationSettings:
    """How faults are named: ``--isolation`` (``sim``: signatures from simulated faults;
    ``none``) and ``--isolation-runs``; ``seed`` shifts the simulated runs' seeds."""

    method: str = "sim"
    runs: int = 2  # simulated runs per fault and severity
    seed: int = 0

    def __post_init__(self) -> None:
        if self.method not in ("sim", "none"):
            raise ConfigError(f"isolation must be 'sim' or 'none', got {self.method!r}")


@dataclass(frozen=True)
class TrainConfig:
    """Everything `monitor train` is told, by group; every group has its defaults."""

    dgrnn: DGRNNSettings = field(default_factory=DGRNNSettings)
    thresholds: ThresholdSettings = field(default_factory=ThresholdSettings)
    statistics: StatisticSettings = field(default_factory=StatisticSettings)
    isolation: IsolationSettings = field(default_factory=IsolationSettings)

    @property
    def with_bias(self) -> bool:
        bias = self.statistics.bias
        return self.dgrnn.preset != "paper" if bias is None else bias

    def spec(self) -> DGRNNSpec:
        return self.dgrnn.spec()
