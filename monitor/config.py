"""config/monitor.yaml: typed, validated once at the edge.

Sections: ``dbc`` and ``model`` (paths, relative to the config file's folder), ``detector``
(horizon), ``alarm`` (debounce and gating).  The live daemon's sections extend this file.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import yaml

from monitor.alarm import AlarmConfig
from monitor.errors import ConfigError
from monitor.resources import resource_path


@dataclass(frozen=True)
class MonitorConfig:
    source: Path
    dbc: Path
    model: Path
    horizon: int | None = None
    alarm: AlarmConfig = field(default_factory=AlarmConfig)


_TOP_KEYS = {"dbc", "model", "detector", "alarm"}


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
            f"{source}: unknown key(s) {', '.join(sorted(unknown))}; "
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
    for key in ("dbc", "model"):
        if key not in data:
            raise ConfigError(f"{source}: missing key {key!r}")
    return MonitorConfig(
        source=source,
        dbc=_path(data["dbc"], "dbc", base, source),
        model=_path(data["model"], "model", base, source),
        horizon=horizon,
        alarm=_alarm(_section(data, "alarm", source), source),
    )
