"""config/monitor.yaml: typed, validated once at the edge.

Sections: ``dbc`` and ``model`` (input files, relative to the config file's folder),
``detector`` (horizon), ``alarm`` (debounce and gating), and for the live daemon ``bus``
(python-can interface, channel, bitrate), ``outputs`` (alarm/status frame rates),
``event_log`` and ``black_box`` (output paths, relative to the working directory the daemon
starts in, so a config shipped inside the installed package never writes into it), and
``storage`` (their disk quota and the disk-writer queue).
``operating``, ``plausibility`` and ``validity`` say which samples
the detector judges; ``loops`` (optional, ``monitor.config.loops``) lists several loops.

Every problem (unknown key, wrong type, missing input file, impossible value) is one
``ConfigError`` naming the file and the key; the CLI turns it into exit 2.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import yaml

from monitor.bus.reader import BusConfig
from monitor.codec.j1939 import dtc as j1939_dtc
from monitor.config.loops import LoopConfig, default_loops, parse_loops
from monitor.detection.alarm import AlarmConfig
from monitor.detection.gating import GatingConfig
from monitor.detection.opstate import OperatingConfig
from monitor.detection.plausibility import PlausibilityConfig
from monitor.errors import ConfigError
from monitor.model.envelope import ValidityConfig
from monitor.resources import resource_path


@dataclass(frozen=True)
class OutputConfig:
    """Rates of the monitor's own frames (sample-clock seconds for alarms)."""

    alarm_repeat_s: float = 1.0  # MON_Alarm repeated this often while in fault
    alarm_max_per_s: float = 10.0  # hard cap on MON_Alarm frames, whatever the state does
    status_period_s: float = 1.0  # MON_Status heartbeat (wall clock)


@dataclass(frozen=True)
class EventLogConfig:
    path: Path = Path("monitor-events.jsonl")
    rotate_mb: float = 8.0  # MB (10^6 bytes): the file is renamed to .1 at this size

    @property
    def rotate_bytes(self) -> int:
        return int(self.rotate_mb * 1e6)


@dataclass(frozen=True)
class BlackBoxConfig:
    directory: Path = Path("monitor-blackbox")
    pre_s: float = 30.0  # raw frames kept from before the alarm
    post_s: float = 10.0  # and recorded after it
    max_frames: int = 200_000  # memory bound of the pre-alarm buffer (~50 s at 4 kHz)
    max_files: int = 50  # oldest files deleted beyond this


@dataclass(frozen=True)
class StorageConfig:
    """Disk use of the daemon's files and the thread that writes them (``monitor.live.storage``,
    ``monitor.live.writer``)."""

    quota_mb: float = 256.0  # MB (10^6 bytes): black boxes + event log files together
    writer_queue: int = 1000  # disk-writer jobs queued at most (black-box work beyond: dropped)
    event_block_s: float = 0.1  # an event waits this long for room in a full queue

    @property
    def quota_bytes(self) -> int:
        return int(self.quota_mb * 1e6)


@dataclass(frozen=True)
class J1939Config:
    """J1939-73 diagnostics: DM1 of the active faults every second, DM2 on request
    (layout and default numbers in monitor/j1939/dtc.py).  A hydraulic fault is one DTC
    (SPN and FMI per fault name); a sensor fault one DTC per stale signal."""

    enabled: bool = False
    source_address: int = 0xA0  # the monitor's J1939 address, as in its MON_* frame IDs
    priority: int = 6  # DM1 priority (J1939-73 default); BAM frames always go at 7
    fault_spn: dict[str, int] = field(default_factory=lambda: dict(j1939_dtc.DEFAULT_FAULT_SPN))
    fault_fmi: dict[str, int] = field(default_factory=lambda: dict(j1939_dtc.DEFAULT_FAULT_FMI))
    sensor_spn: dict[str, int] = field(default_factory=lambda: dict(j1939_dtc.DEFAULT_SENSOR_SPN))
    sensor_fmi: int = j1939_dtc.DEFAULT_SENSOR_FMI
    check_fmi: dict[str, int] = field(default_factory=lambda: dict(j1939_dtc.DEFAULT_CHECK_FMI))
    fault_lamp: str = "amber"  # none, protect, amber, red or mil; :slow / :fast to flash
    sensor_lamp: str = "amber"
    repeat_when_clear: bool = True  # the no-DTC DM1 every second (else only on the change)
    bam_gap_s: float = 0.05  # between BAM data packets (J1939-21: 50 to 200 ms)
    max_frames_per_s: float = 10.0  # token bucket over every J1939 frame we send

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
    operating: OperatingConfig = field(default_factory=OperatingConfig)
    plausibility: PlausibilityConfig = field(default_factory=PlausibilityConfig)
    validity: ValidityConfig = field(default_factory=ValidityConfig)
    loops: tuple[LoopConfig, ...] = ()  # as written in the file; empty: no ``loops`` section

    @property
    def gating(self) -> GatingConfig:
        return GatingConfig(self.operating, self.plausibility, self.validity)

    @property
    def monitored_loops(self) -> tuple[LoopConfig, ...]:
        """The loops the daemon monitors: ``loops``, or the one ``boom`` loop of ``model``."""
        return self.loops or default_loops(self.model, self.j1939.source_address)


_TOP_KEYS = {
    "dbc", "model", "detector", "alarm", "bus", "outputs", "event_log", "black_box",
    "storage",
    "j1939",
    "operating", "plausibility", "validity",
    "loops",
}  # fmt: skip


def _path(value: Any, key: str, base: Path, source: Path) -> Path:
    if not isinstance(value, str) or not value:
        raise ConfigError(f"{source}: {key} must be a file path, got {value!r}")
    p = Path(value)
    p = p if p.is_absolute() else base / p
    if not p.is_file():
        raise ConfigError(f"{source}: {key}: no such file {p}")
    return p


def _section(data: dict[str, Any], name: str, source: Path) -> dict[str, Any]:
    sec = data.get(name) or {}
    if not isinstance(sec, dict):
        raise ConfigError(f"{source}: section {name!r} must be a mapping")
    return sec


def _alarm(sec: dict[str, Any], source: Path) -> AlarmConfig:
    known = {f.name: f.type for f in fields(AlarmConfig)}
    values: dict[str, Any] = {}
    for key, raw in sec.items():
        if key not in known:
            raise ConfigError(f"{source}: unknown key alarm.{key}; known: {', '.join(known)}")
        default = getattr(AlarmConfig(), key)
        if isinstance(raw, bool) or not isinstance(raw, (int, float)):
            raise ConfigError(f"{source}: alarm.{key} must be a number, got {raw!r}")
        if isinstance(default, int) and not float(raw).is_integer():
            raise ConfigError(f"{source}: alarm.{key} must be a whole number, got {raw!r}")
        values[key] = type(default)(raw)
    try:
        return AlarmConfig(**values)
    except ConfigError as exc:
        raise ConfigError(f"{source}: {exc}") from None


# -- generic typed sections -----------------------------------------------------------------

Check = Callable[[Any], bool]
_POSITIVE: Check = lambda v: v > 0  # noqa: E731
_NON_NEG: Check = lambda v: v >= 0  # noqa: E731
# key -> (kind, check, what the check demands); kind: "str", "int", "float", "bool", "path",
# "options"
_BUS = {
    "interface": ("str", None, ""),
    "channel": ("str", None, ""),
    "bitrate": ("int", lambda v: 10_000 <= v <= 1_000_000, "between 10000 and 1000000"),
    "queue_frames": ("int", lambda v: v >= 100, ">= 100"),
    "kernel_filters": ("bool", None, ""),
    "silent_s": ("float", _POSITIVE, "> 0"),
    "time_scale": ("float", lambda v: 0.01 <= v <= 100, "between 0.01 and 100"),
    "options": ("options", None, ""),
    "reopen_initial_s": ("float", lambda v: 0.001 <= v <= 3600, "between 0.001 and 3600"),
    "reopen_max_s": ("float", lambda v: 0.001 <= v <= 3600, "between 0.001 and 3600"),
}
_OUTPUTS = {
    "alarm_repeat_s": ("float", _POSITIVE, "> 0"),
    "alarm_max_per_s": ("float", _POSITIVE, "> 0"),
    "status_period_s": ("float", _POSITIVE, "> 0"),
}
_EVENT_LOG = {
    "path": ("path", None, ""),
    "rotate_mb": ("float", lambda v: v >= 0.001, ">= 0.001 (1 kB)"),
}
_BLACK_BOX = {
    "directory": ("path", None, ""),
    "pre_s": ("float", _NON_NEG, ">= 0"),
    "post_s": ("float", _NON_NEG, ">= 0"),
    "max_frames": ("int", _POSITIVE, ">= 1"),
    "max_files": ("int", _POSITIVE, ">= 1"),
}
_STORAGE = {
    "quota_mb": ("float", _POSITIVE, "> 0"),
    "writer_queue": ("int", lambda v: v >= 10, ">= 10"),
    "event_block_s": ("float", lambda v: 0 <= v <= 5, "between 0 and 5"),
}

_J1939 = {
    "enabled": ("bool", None, ""),
    "source_address": ("int", lambda v: 0 <= v <= 253, "0..253 (254 null, 255 global)"),
    "priority": ("int", lambda v: 0 <= v <= 7, "0..7"),
    "fault_spn": ("options", None, ""),
    "fault_fmi": ("options", None, ""),
    "sensor_spn": ("options", None, ""),
    "sensor_fmi": ("int", lambda v: 0 <= v <= j1939_dtc.FMI_MAX, "0..31"),
    "check_fmi": ("options", None, ""),
    "fault_lamp": ("str", None, ""),
    "sensor_lamp": ("str", None, ""),
    "repeat_when_clear": ("bool", None, ""),
    "bam_gap_s": ("float", lambda v: 0.05 <= v <= 0.2, "between 0.05 and 0.2 (J1939-21)"),
    "max_frames_per_s": ("float", lambda v: v >= 2, ">= 2"),
}
_OPERATING = {
    "warmup_oil_c": ("float", lambda v: -40 <= v <= 150, "within -40..150 (degC)"),
    "warmup_hysteresis_c": ("float", _NON_NEG, ">= 0 (degC)"),
}
_PLAUSIBILITY = {f.name: ("float", _NON_NEG, ">= 0") for f in fields(PlausibilityConfig)} | {
    "pressure_min_bar": ("float", None, ""),
    "pressure_max_bar": ("float", _POSITIVE, "> 0 (bar)"),
    "flow_max_lpm": ("float", _POSITIVE, "> 0 (L/min)"),
}
_VALIDITY = {
    "gate": ("bool", None, ""),
    "margin_fraction": ("float", _NON_NEG, ">= 0"),
    "margin_pct": ("float", _NON_NEG, ">= 0 (%)"),
    "margin_rpm": ("float", _NON_NEG, ">= 0 (rpm)"),
    "margin_c": ("float", _NON_NEG, ">= 0 (degC)"),
    "min_bin_share": ("float", lambda v: 0 <= v <= 1, "within 0..1"),
}


def _checked_section(cls: type, spec: dict, data: dict[str, Any], name: str, source: Path) -> Any:
    """A typed section whose dataclass also checks values together (one ConfigError)."""
    try:
        return _typed(cls, spec, _section(data, name, source), name, source)
    except ConfigError as exc:
        text = str(exc)
        raise ConfigError(text if text.startswith(f"{source}:") else f"{source}: {text}") from None


def _value(kind: str, raw: Any, where: str, source: Path) -> Any:
    def bad(what: str) -> ConfigError:
        return ConfigError(f"{source}: {where} must be {what}, got {raw!r}")

    if kind == "str":
        if not isinstance(raw, str) or not raw:
            raise bad("a non-empty string")
        return raw
    if kind == "path":
        if not isinstance(raw, str) or not raw:
            raise bad("a path")
        return Path(raw).expanduser()
    if kind == "bool":
        if not isinstance(raw, bool):
            raise bad("true or false")
        return raw
    if kind == "options":
        if not isinstance(raw, dict) or not all(
            isinstance(k, str) and isinstance(v, (str, int, float, bool)) for k, v in raw.items()
        ):
            raise bad("a mapping of names to scalar values")
        return dict(raw)
    if isinstance(raw, bool) or not isinstance(raw, (int, float)):
        raise bad("a number")
    if kind == "int":
        if not float(raw).is_integer():
            raise bad("a whole number")
        return int(raw)
    return float(raw)


def _typed(cls: type, spec: dict, sec: dict[str, Any], name: str, source: Path) -> Any:
    values: dict[str, Any] = {}
    for key, raw in sec.items():
        if key not in spec:
            raise ConfigError(f"{source}: unknown key {name}.{key}; known: {', '.join(spec)}")
        kind, check, demand = spec[key]
        v = _value(kind, raw, f"{name}.{key}", source)
        if check is not None and not check(v):
            raise ConfigError(f"{source}: {name}.{key} must be {demand}, got {raw!r}")
        values[key] = v
    try:
        return cls(**values)
    except ConfigError as exc:  # a check across keys in the class itself
        raise ConfigError(f"{source}: {exc}") from None


def load_config(path: str | Path | None = None) -> MonitorConfig:
    """Load and validate a monitor config (default: the shipped config/monitor.yaml)."""
    source = Path(path) if path is not None else resource_path("config", "monitor.yaml")
    try:
        data = yaml.safe_load(source.read_text(encoding="utf-8")) or {}
    except OSError as exc:
        raise ConfigError(f"{source}: cannot read config: {exc.strerror}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{source}: not valid YAML: {exc}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: expected a mapping at the top level")
    unknown = set(data) - _TOP_KEYS
    if unknown:
        raise ConfigError(
            f"{source}: unknown key(s) {', '.join(sorted(map(str, unknown)))}; "
            f"known: {', '.join(sorted(_TOP_KEYS))}"
        )
    base = source.parent
    det = _section(data, "detector", source)
    extra = set(det) - {"horizon"}
    if extra:
        raise ConfigError(f"{source}: unknown key(s) detector.{', detector.'.join(sorted(extra))}")
    horizon = det.get("horizon")
    if horizon is not None and (
        isinstance(horizon, bool) or not isinstance(horizon, int) or horizon < 1
    ):
        raise ConfigError(f"{source}: detector.horizon must be a whole number >= 1")
    black_box = _typed(
        BlackBoxConfig, _BLACK_BOX, _section(data, "black_box", source), "black_box", source
    )
    bus = _typed(BusConfig, _BUS, _section(data, "bus", source), "bus", source)
    if bus.reopen_max_s < bus.reopen_initial_s:
        raise ConfigError(f"{source}: bus.reopen_max_s ({bus.reopen_max_s}) must be >= "
                          f"bus.reopen_initial_s ({bus.reopen_initial_s})")  # fmt: skip
    event_log = _typed(
        EventLogConfig, _EVENT_LOG, _section(data, "event_log", source), "event_log", source
    )
    storage = _typed(StorageConfig, _STORAGE, _section(data, "storage", source), "storage", source)
    if storage.quota_mb <= 2 * event_log.rotate_mb:
        raise ConfigError(
            f"{source}: storage.quota_mb ({storage.quota_mb:g}) must be more than twice "
            f"event_log.rotate_mb ({event_log.rotate_mb:g}): the current event log and one "
            "rotated file must fit"
        )
    j1939 = _checked_section(J1939Config, _J1939, data, "j1939", source)
    loops: tuple[LoopConfig, ...] = ()
    if "loops" in data:
        loops = parse_loops(data["loops"], source, lambda v, k: _path(v, k, base, source),
                            j1939.source_address)  # fmt: skip
    return MonitorConfig(
        source=source,
        # Without ``dbc`` or ``model`` the shipped ones (the reference boom loop).
        dbc=_path(data["dbc"], "dbc", base, source) if "dbc" in data
        else resource_path("dbc", "monitor.dbc"),
        model=_path(data["model"], "model", base, source) if "model" in data
        else resource_path("config", "boom_default.model.npz"),
        horizon=horizon,
        alarm=_alarm(_section(data, "alarm", source), source),
        bus=bus,
        outputs=_typed(
            OutputConfig, _OUTPUTS, _section(data, "outputs", source), "outputs", source
        ),
        event_log=event_log,
        black_box=black_box,
        storage=storage,
        j1939=j1939,
        operating=_checked_section(OperatingConfig, _OPERATING, data, "operating", source),
        plausibility=_checked_section(
            PlausibilityConfig, _PLAUSIBILITY, data, "plausibility", source
        ),
        validity=_checked_section(ValidityConfig, _VALIDITY, data, "validity", source),
        loops=loops,
    )
