"""config/monitor.yaml: typed, validated once at the edge.

Sections: ``dbc`` and ``model`` (input files, relative to the config file's folder),
``detector`` (horizon), ``alarm`` (debounce and gating), and for the live daemon ``bus``
(python-can interface, channel, bitrate), ``outputs`` (alarm/status frame rates),
``event_log`` and ``black_box`` (output paths, relative to the working directory the daemon
starts in, so a config shipped inside the installed package never writes into it), and
``storage`` (their disk quota and the disk-writer queue).
``operating``, ``plausibility`` and ``validity`` say which samples
the detector judges; ``loops`` (optional, ``monitor.config.loops``) lists several loops;
``machine`` (optional) names the simulator YAML of the machine of a config without loops,
against which a model's recorded machine is checked (``monitor.model.machinecard``);
``machine_id`` (optional) names the machine monitored (its serial), which ``monitor train``
records in the model and which a model must have been commissioned on to raise hydraulic
alarms (``machinecard.reference_reason``).

Every problem (unknown key, wrong type, missing input file, impossible value) is one
``ConfigError`` naming the file and the key; the CLI turns it into exit 2.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from monitor.bus.reader import BusConfig
from monitor.codec.j1939 import dtc as j1939_dtc
from monitor.config.loops import LoopConfig, default_loops, parse_loops
from monitor.config.pump import PumpSection, parse_pump
from monitor.detection.alarm import AlarmConfig
from monitor.detection.gating import GatingConfig
from monitor.detection.opstate import OperatingConfig
from monitor.detection.plausibility import PlausibilityConfig
from monitor.errors import ConfigError
from monitor.model.envelope import ValidityConfig
from monitor.resources import resource_path
from monitor.schema.sections import keys_text, setting, shown, typed
from monitor.schema.yamlfile import read_yaml
from monitor.sim.machine import MachineParams, load_machine


def _POSITIVE(v: float) -> bool:  # noqa: N802 - a constant-like check
    return v > 0


def _NON_NEG(v: float) -> bool:  # noqa: N802
    return v >= 0


@dataclass(frozen=True)
class OutputConfig:
    """Rates of the monitor's own frames (sample-clock seconds for alarms)."""

    alarm_repeat_s: float = setting(
        1.0,
        check=_POSITIVE,
        demand="> 0",
        unit="s",
        doc="MON_Alarm repeated this often while in fault",
    )
    alarm_max_per_s: float = setting(
        10.0, check=_POSITIVE, demand="> 0", unit="1/s", doc="hard cap on MON_Alarm frames"
    )
    status_period_s: float = setting(
        1.0, check=_POSITIVE, demand="> 0", unit="s", doc="MON_Status heartbeat (wall clock)"
    )
    frames_max_per_s: float = setting(
        50.0,
        check=_POSITIVE,
        demand="> 0",
        unit="1/s",
        doc="hard cap on every frame the monitor sends (alarms, status, J1939), wall clock "
        "(divided by bus.time_scale below 1); frames over it are dropped and counted",
    )


@dataclass(frozen=True)
class EventLogConfig:
    path: Path = setting(Path("monitor-events.jsonl"), doc="append-only JSON lines, fsynced")
    rotate_mb: float = setting(
        8.0,
        check=lambda v: v >= 0.001,
        demand=">= 0.001 (1 kB)",
        unit="MB",
        doc="the file is renamed to .1 at this size",
    )

    @property
    def rotate_bytes(self) -> int:
        return int(self.rotate_mb * 1e6)


@dataclass(frozen=True)
class BlackBoxConfig:
    directory: Path = setting(Path("monitor-blackbox"), doc="one candump file per alarm")
    pre_s: float = setting(
        30.0, check=_NON_NEG, demand=">= 0", unit="s", doc="raw frames kept from before the alarm"
    )
    post_s: float = setting(
        10.0, check=_NON_NEG, demand=">= 0", unit="s", doc="and recorded after it"
    )
    max_frames: int = setting(
        200_000,
        check=_POSITIVE,
        demand=">= 1",
        unit="frames",
        doc="bound of the pre-alarm buffer (~50 s at 4 kHz)",
    )
    max_files: int = setting(
        50, check=_POSITIVE, demand=">= 1", doc="oldest (by alarm seq) deleted beyond this"
    )


@dataclass(frozen=True)
class StorageConfig:
    """Disk use of the daemon's files and the thread that writes them (``monitor.live.storage``,
    ``monitor.live.writer``)."""

    quota_mb: float = setting(
        256.0,
        check=_POSITIVE,
        demand="> 0",
        unit="MB",
        doc="black boxes + event log files together",
    )
    writer_queue: int = setting(
        1000,
        check=lambda v: v >= 10,
        demand=">= 10",
        doc="disk-writer jobs queued at most (black-box work beyond: dropped)",
    )
    event_block_s: float = setting(
        0.1,
        check=lambda v: 0 <= v <= 5,
        demand="between 0 and 5",
        unit="s",
        doc="an event waits this long for room in a full queue",
    )

    @property
    def quota_bytes(self) -> int:
        return int(self.quota_mb * 1e6)


@dataclass(frozen=True)
class J1939Config:
    """J1939-73 diagnostics: DM1 of the active faults every second, DM2 on request
    (layout and default numbers in monitor/j1939/dtc.py).  A hydraulic fault is one DTC
    (SPN and FMI per fault name); a sensor fault one DTC per stale signal."""

    enabled: bool = False
    source_address: int = setting(
        0xA0,
        check=lambda v: 0 <= v <= 253,
        demand="0..253 (254 null, 255 global)",
        doc="our J1939 address, as in the MON_* frame IDs",
    )
    priority: int = setting(
        6,
        check=lambda v: 0 <= v <= 7,
        demand="0..7",
        doc="DM1 priority (J1939-73); BAM frames go at 7",
    )
    fault_spn: dict[str, int] = field(default_factory=lambda: dict(j1939_dtc.DEFAULT_FAULT_SPN))
    fault_fmi: dict[str, int] = field(default_factory=lambda: dict(j1939_dtc.DEFAULT_FAULT_FMI))
    sensor_spn: dict[str, int] = field(default_factory=lambda: dict(j1939_dtc.DEFAULT_SENSOR_SPN))
    sensor_fmi: int = setting(
        j1939_dtc.DEFAULT_SENSOR_FMI, check=lambda v: 0 <= v <= 31, demand="0..31"
    )
    check_fmi: dict[str, int] = field(default_factory=lambda: dict(j1939_dtc.DEFAULT_CHECK_FMI))
    fault_lamp: str = "amber"  # none, protect, amber, red or mil; :slow / :fast to flash
    sensor_lamp: str = "amber"
    repeat_when_clear: bool = True  # the no-DTC DM1 every second (else only on the change)
    bam_gap_s: float = setting(
        0.05,
        check=lambda v: 0.05 <= v <= 0.2,
        demand="between 0.05 and 0.2 (J1939-21)",
        unit="s",
        doc="between BAM data packets",
    )
    max_frames_per_s: float = setting(
        10.0,
        check=lambda v: v >= 2,
        demand=">= 2",
        unit="1/s",
        doc="cap on J1939 frames in any second",
    )

    def __post_init__(self) -> None:
        dtc = j1939_dtc
        names = tuple(dtc.DEFAULT_FAULT_SPN)
        signals = tuple(dtc.DEFAULT_SENSOR_SPN)
        # Given maps replace single entries of the defaults, so one line can move one SPN.
        for key, known, top, default in (
            ("fault_spn", names, dtc.SPN_MAX, dtc.DEFAULT_FAULT_SPN),
            ("fault_fmi", names, dtc.FMI_MAX, dtc.DEFAULT_FAULT_FMI),
            ("sensor_spn", signals, dtc.SPN_MAX, dtc.DEFAULT_SENSOR_SPN),
            ("check_fmi", tuple(dtc.DEFAULT_CHECK_FMI), dtc.FMI_MAX, dtc.DEFAULT_CHECK_FMI),
        ):
            given = dtc.check_number_map(getattr(self, key), known, top, f"j1939.{key}")
            object.__setattr__(self, key, default | given)
        for key in ("fault_lamp", "sensor_lamp"):
            dtc.Lamp.parse(getattr(self, key), f"j1939.{key}")


@dataclass(frozen=True)
class DetectorSection:
    """``detector:`` section."""

    horizon: int | None = setting(
        None,
        check=lambda v: v is None or v >= 1,
        demand=">= 1",
        unit="samples",
        doc="prediction horizon p (eq. 7); default: the model's",
    )


@dataclass(frozen=True)
class MachineSection:
    """The machine monitored: ``machine_id`` (its id, None: not declared) and ``machine``
    (the simulator YAML of the machine of the one loop of a config without ``loops``, and
    its parameters)."""

    machine_id: str | None = None
    source: Path | None = None
    params: MachineParams | None = None


@dataclass(frozen=True)
class MonitorConfig:
    source: Path
    dbc: Path
    model: Path
    horizon: int | None = None
    alarm: AlarmConfig = field(default_factory=AlarmConfig)
    bus: BusConfig = field(default_factory=BusConfig)
    outputs: OutputConfig = field(default_factory=OutputConfig)
    event_log: EventLogConfig = field(default_factory=EventLogConfig)
    black_box: BlackBoxConfig = field(default_factory=BlackBoxConfig)
    storage: StorageConfig = field(default_factory=StorageConfig)
    j1939: J1939Config = field(default_factory=J1939Config)
    #: The ``operating``, ``plausibility`` and ``validity`` sections: which samples are judged.
    gating: GatingConfig = field(default_factory=GatingConfig)
    loops: tuple[LoopConfig, ...] = ()  # as written in the file; empty: no ``loops`` section
    machine: MachineSection = field(default_factory=MachineSection)
    #: ``pump:``: the shared pump's margin law (``monitor train --pump``), its alarm frame.
    pump: PumpSection | None = None

    @property
    def machine_id(self) -> str | None:
        """The machine monitored, as the config declares it (None: not declared)."""
        return self.machine.machine_id

    @property
    def monitored_loops(self) -> tuple[LoopConfig, ...]:
        """The loops the daemon monitors: ``loops``, or the one ``boom`` loop of ``model``."""
        return self.loops or default_loops(
            self.model, self.j1939.source_address, self.machine.params, self.machine.source
        )


_TOP_KEYS = {
    "dbc",
    "model",
    "detector",
    "alarm",
    "bus",
    "outputs",
    "event_log",
    "black_box",
    "storage",
    "j1939",
    "operating",
    "plausibility",
    "validity",
    "loops",
    "machine",
    "machine_id",
    "pump",
}


def _path(value: Any, key: str, base: Path, source: Path) -> Path:
    if not isinstance(value, str) or not value:
        raise ConfigError(f"{source}: {key} must be a file path, got {shown(value)}")
    p = Path(value)
    p = p if p.is_absolute() else base / p
    if not p.is_file():
        raise ConfigError(f"{source}: {key}: no such file {p}")
    return p


def load_config(path: str | Path | None = None) -> MonitorConfig:
    """Load and validate a monitor config (default: the shipped config/monitor.yaml)."""
    source = Path(path) if path is not None else resource_path("config", "monitor.yaml")
    data = read_yaml(source, "config") or {}
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: expected a mapping at the top level")
    unknown = set(data) - _TOP_KEYS
    if unknown:
        raise ConfigError(
            f"{source}: unknown key(s) {keys_text(unknown)}; known: {', '.join(sorted(_TOP_KEYS))}"
        )

    def section(cls: type, name: str) -> Any:
        return typed(cls, data.get(name), name, source)

    horizon = section(DetectorSection, "detector").horizon
    black_box = section(BlackBoxConfig, "black_box")
    bus, event_log, storage = _daemon_sections(section, source)
    j1939 = section(J1939Config, "j1939")
    files = _Files(data, source)
    machine = files.optional("machine")
    loops: tuple[LoopConfig, ...] = ()
    if "loops" in data:
        loops = parse_loops(data["loops"], source, files.path, j1939.source_address)
    return MonitorConfig(
        source=source,
        # Without ``dbc`` or ``model`` the shipped ones (the reference boom loop).
        dbc=files.given("dbc") or resource_path("dbc", "monitor.dbc"),
        model=files.given("model") or resource_path("config", "boom_default.model.npz"),
        horizon=horizon,
        alarm=section(AlarmConfig, "alarm"),
        bus=bus,
        outputs=section(OutputConfig, "outputs"),
        event_log=event_log,
        black_box=black_box,
        storage=storage,
        j1939=j1939,
        gating=GatingConfig(
            section(OperatingConfig, "operating"),
            section(PlausibilityConfig, "plausibility"),
            section(ValidityConfig, "validity"),
        ),
        loops=loops,
        pump=parse_pump(data.get("pump"), source, files.path),
        machine=MachineSection(
            _machine_id(data.get("machine_id"), source),
            machine,
            None if machine is None else load_machine(machine),
        ),
    )


def _machine_id(value: Any, source: Path) -> str | None:
    """``machine_id``: a non-empty text (a serial written as a number would lose its
    leading zeros, so it must be quoted)."""
    if value is None or (isinstance(value, str) and value.strip()):
        return None if value is None else value.strip()
    raise ConfigError(
        f"{source}: machine_id must be a text naming the machine (quote a number: "
        f"machine_id: '0042'), got {shown(value)}"
    )


def _daemon_sections(
    section: Callable[[type, str], Any], source: Path
) -> tuple[BusConfig, EventLogConfig, StorageConfig]:
    """``bus``, ``event_log`` and ``storage``, checked against each other."""
    bus = section(BusConfig, "bus")
    if bus.reopen_max_s < bus.reopen_initial_s:
        raise ConfigError(
            f"{source}: bus.reopen_max_s ({bus.reopen_max_s}) must be >= "
            f"bus.reopen_initial_s ({bus.reopen_initial_s})"
        )
    event_log = section(EventLogConfig, "event_log")
    storage = section(StorageConfig, "storage")
    if storage.quota_mb <= 2 * event_log.rotate_mb:
        raise ConfigError(
            f"{source}: storage.quota_mb ({storage.quota_mb:g}) must be more than twice "
            f"event_log.rotate_mb ({event_log.rotate_mb:g}): the current event log and one "
            "rotated file must fit"
        )
    return bus, event_log, storage


@dataclass(frozen=True)
class _Files:
    """The config's input files, relative to its folder, each checked to exist."""

    data: dict[str, Any]
    source: Path

    def path(self, value: Any, key: str) -> Path:
        return _path(value, key, self.source.parent, self.source)

    def given(self, key: str) -> Path | None:
        """The top-level key's file (None: no such key; a null value is an error)."""
        return self.path(self.data[key], key) if key in self.data else None

    def optional(self, key: str) -> Path | None:
        """The top-level key's file (None: no such key, or null)."""
        value = self.data.get(key)
        return None if value is None else self.path(value, key)
