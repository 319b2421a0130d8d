"""The ``plausibility:`` section: one record per check (``monitor.detection.plausibility``
describes the checks) and the sensor ranges they judge against.  The YAML keeps its keys
flat; each is a setting of one record."""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np

from monitor.errors import ConfigError
from monitor.schema.sections import setting
from monitor.signals import SIGNAL_NAMES

#: Kernel column order: the contract signals (SpoolCmd, PumpDispCmd, EngineSpeed, OilTemp,
#: PP, PA, PB, QP).
COLUMNS: tuple[str, ...] = SIGNAL_NAMES
#: The transducers' columns: the pressures and the flow.
_PRESSURES = tuple(COLUMNS.index(n) for n in ("PP", "PA", "PB"))
_FLOW = COLUMNS.index("QP")
#: Sensor ranges of the shipped DBC (dbc/monitor.dbc; tests hold them equal).
DBC_RANGES: dict[str, tuple[float, float]] = {
    "SpoolCmd": (-100.0, 100.0),
    "PumpDispCmd": (0.0, 100.0),
    "EngineSpeed": (0.0, 3000.0),
    "OilTemp": (-40.0, 150.0),
    "PP": (0.0, 400.0),
    "PA": (0.0, 400.0),
    "PB": (0.0, 400.0),
    "QP": (0.0, 60.0),
}


@dataclass(frozen=True)
class RangeCheck:
    """``signal_range``: the sensor ranges and how long a reading may lie outside."""

    pressure_min_bar: float = 0.0  # PP, PA, PB sensor range (default: the DBC's)
    pressure_max_bar: float = 400.0
    flow_max_lpm: float = 60.0  # QP sensor range upper end (lower end 0)
    # 4-20 mA transducers sit +-0.5 % FS off zero and their noise crosses zero.
    range_tolerance_fs: float = 0.01  # share of full scale PP/PA/PB/QP may read below range
    range_s: float = 0.1


@dataclass(frozen=True)
class FrozenCheck:
    """``frozen``: bit-identical readings with the engine on."""

    frozen_s: float = 1.0


@dataclass(frozen=True)
class StuckCheck:
    """``stuck``: a reading inside its band for this long of moving time."""

    stuck_s: float = 20.0
    stuck_band_bar: float = 1.5
    stuck_band_lpm: float = 0.5


@dataclass(frozen=True)
class Motion:
    """What counts as the machine moving (``stuck``; the rest check needs the spool centred)."""

    move_spool_pct: float = 20.0
    move_flow_lpm: float = 2.0


@dataclass(frozen=True)
class RelationCheck:
    """``pump_below_port``: PP >= max(PA, PB) - margin while the spool is open."""

    relation_spool_pct: float = 20.0
    relation_margin_bar: float = 10.0
    relation_s: float = 1.0


@dataclass(frozen=True)
class RestCheck:
    """``rest_offset``: engine off and spool centred this long, the pressures near tank."""

    rest_settle_s: float = 30.0
    rest_max_bar: float = 5.0


#: The pump systems the relation checks know (``PumpSystem``).
PUMP_SYSTEMS: tuple[str, ...] = ("pressure_compensated", "load_sensing")


@dataclass(frozen=True)
class PumpSystem:
    """What feeds the loop, which decides what the pressures prove (``pump_below_port`` and
    the frozen check of QP at zero).  ``pressure_compensated``: one loop on its own pump
    held at its compensator setting, far above any port it feeds (the reference machine).
    ``load_sensing``: a pump shared by several sections, held ``ls_margin_bar`` above the
    highest load pressure of the open sections, at standby when all are closed."""

    pump_system: str = setting(
        "pressure_compensated",
        check=lambda v: v in PUMP_SYSTEMS,
        demand=" or ".join(PUMP_SYSTEMS),
        doc="the pump that feeds the loop: its own compensated pump, or a load-sensing "
        "pump shared with other sections",
    )
    ls_margin_bar: float = setting(
        20.0,
        check=lambda v: 0 < v <= 100,
        demand="within 0..100 (above 0)",
        unit="bar",
        doc="load_sensing: the pump's margin over the highest load pressure",
    )

    def __post_init__(self) -> None:
        if self.pump_system not in PUMP_SYSTEMS:
            raise ConfigError(
                f"plausibility.pump_system must be {' or '.join(PUMP_SYSTEMS)}, "
                f"got {self.pump_system!r}"
            )
        if not 0 < self.ls_margin_bar <= 100:
            raise ConfigError("plausibility.ls_margin_bar must be within 0..100 (above 0)")

    @property
    def load_sensing(self) -> bool:
        return self.pump_system == "load_sensing"


@dataclass(frozen=True)
class PlausibilityConfig:
    """``plausibility:`` section (units in the names; a time of 0 switches its check off).

    One record per check (and ``motion``, what counts as moving); the YAML keeps the keys
    flat, each a setting of one record (``monitor.schema.sections.keys``)."""

    signal_range: RangeCheck = field(default_factory=RangeCheck)
    frozen: FrozenCheck = field(default_factory=FrozenCheck)
    stuck: StuckCheck = field(default_factory=StuckCheck)
    motion: Motion = field(default_factory=Motion)
    relation: RelationCheck = field(default_factory=RelationCheck)
    rest: RestCheck = field(default_factory=RestCheck)
    pump: PumpSystem = field(default_factory=PumpSystem)

    def __post_init__(self) -> None:
        for group in (
            self.signal_range,
            self.frozen,
            self.stuck,
            self.motion,
            self.relation,
            self.rest,
        ):
            for f in fields(group):
                if f.name != "pressure_min_bar" and not getattr(group, f.name) >= 0:
                    raise ConfigError(f"plausibility.{f.name} must be >= 0")
        r = self.signal_range
        if not r.pressure_max_bar > r.pressure_min_bar:
            raise ConfigError("plausibility.pressure_max_bar must be above pressure_min_bar")
        if r.flow_max_lpm <= 0:
            raise ConfigError("plausibility.flow_max_lpm must be > 0")
        if not r.range_tolerance_fs <= 0.1:
            raise ConfigError(
                f"plausibility.range_tolerance_fs is a share of full scale "
                f"within 0..0.1 (0.01 = 1 %), got "
                f"{r.range_tolerance_fs}"
            )

    def limits(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) sensor range per column (COLUMNS order)."""
        lo = np.array([DBC_RANGES[n][0] for n in COLUMNS])
        hi = np.array([DBC_RANGES[n][1] for n in COLUMNS])
        for c in _PRESSURES:
            lo[c], hi[c] = self.signal_range.pressure_min_bar, self.signal_range.pressure_max_bar
        hi[_FLOW] = self.signal_range.flow_max_lpm
        return lo, hi

    def range_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """(lowest, highest) reading per column that is in range: the transducers (PP, PA,
        PB, QP) down to ``range_tolerance_fs`` of full scale below their lower limit and
        strictly below full scale (a reading at it is pinned); the others their limits."""
        lo, hi = self.limits()
        for c in (*_PRESSURES, _FLOW):
            lo[c] -= self.signal_range.range_tolerance_fs * (hi[c] - lo[c])
            hi[c] = np.nextafter(hi[c], -np.inf)
        return lo, hi
