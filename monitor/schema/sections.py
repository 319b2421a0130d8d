"""Typed configuration sections, declared once: each setting is a dataclass field whose
metadata says what a value must be (``setting(default, check=..., demand=..., unit=...)``);
``typed`` validates a YAML mapping against the dataclass and builds it.  A section may be
made of records (one per check, say) while its YAML stays flat: ``keys`` says which record
each key belongs to.

The kind of a value follows the field's annotation: ``str``, ``int``, ``float``, ``bool``,
``Path`` (a file or folder name) or ``dict[...]`` (a mapping of names to scalars).  Numbers
must be finite: NaN and infinity never pass as configuration.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import MISSING, Field, field, fields, is_dataclass
from pathlib import Path
from typing import Any, get_type_hints

from monitor.errors import ConfigError


def shown(v: Any, limit: int = 60) -> str:
    """``repr`` of a value for a message, cut to ``limit`` characters (a YAML value may be a
    megabyte, and a message is one line)."""
    r = repr(v)
    return r if len(r) <= limit else r[: limit - 3] + "..."


def key_text(k: Any) -> str:
    """A key for a message: as written when short and printable, else quoted and cut."""
    s = str(k)
    return s if s.isprintable() and len(s) <= 40 else shown(s, 40)


def keys_text(keys: Any) -> str:
    """Keys for a message, sorted, at most five named."""
    names = sorted(map(key_text, keys))
    more = f", ... ({len(names)} in all)" if len(names) > 5 else ""
    return ", ".join(names[:5]) + more


Check = Callable[[Any], bool]


def setting(
    default: Any = MISSING,
    *,
    check: Check | None = None,
    demand: str = "",
    unit: str | None = None,
    doc: str | None = None,
    factory: Callable[[], Any] | None = None,
) -> Any:
    """A dataclass field with its validation: ``check(value)`` must hold, ``demand`` says
    what it asks for in the error message; ``unit`` and ``doc`` go to the reference docs."""
    meta = {"check": check, "demand": demand, "unit": unit, "doc": doc}
    if factory is not None:
        return field(default_factory=factory, metadata=meta)
    return field(default=default, metadata=meta)


def between(lo: float, hi: float, unit: str = "") -> tuple[Check, str]:
    """(check, demand) for lo <= v <= hi."""
    return (lambda v: lo <= v <= hi), f"within {lo:g}..{hi:g}{' ' + unit if unit else ''}"


def _kind(annotation: Any) -> str:
    text = annotation if isinstance(annotation, str) else getattr(annotation, "__name__", "")
    text = text.replace(" ", "").replace("|None", "")
    if text.startswith("dict"):
        return "options"
    return {"Path": "path", "str": "str", "int": "int", "float": "float", "bool": "bool"}.get(
        text, "any"
    )


def value(kind: str, raw: Any, where: str, source: Path | str) -> Any:
    """``raw`` from YAML as ``kind``, or one ConfigError naming file, key and value."""

    def bad(what: str) -> ConfigError:
        shown = repr(raw) if len(repr(raw)) <= 60 else repr(raw)[:57] + "..."
        return ConfigError(f"{source}: {where} must be {what}, got {shown}")

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
    if kind == "any":
        return raw
    if isinstance(raw, bool) or not isinstance(raw, (int, float)):
        raise bad("a number")
    try:  # a 4,000-digit integer is a Python int, beyond any float
        finite = math.isfinite(raw)
    except OverflowError:
        finite = False
    if not finite:
        raise bad("a finite number")
    if kind == "int":
        if not float(raw).is_integer():
            raise bad("a whole number")
        return int(raw)
    return float(raw)


def records(cls: type) -> dict[str, type]:
    """The nested records of a section made of records (field name -> record class), as
    ``plausibility`` is one per check; empty for a section of plain settings."""
    try:
        hints = get_type_hints(cls)
    except (NameError, TypeError):
        return {}
    inits = [f for f in fields(cls) if f.init]
    kinds = {f.name: hints.get(f.name) for f in inits}
    if not inits or not all(isinstance(k, type) and is_dataclass(k) for k in kinds.values()):
        return {}
    return {n: k for n, k in kinds.items() if isinstance(k, type)}


def keys(cls: type) -> dict[str, tuple[str | None, Field[Any]]]:
    """A section's YAML keys in declaration order -> (record field, setting field).  A
    section made of records keeps its YAML flat: every key is a setting of one record
    (their names are unique), the record field None otherwise."""
    groups = records(cls)
    if not groups:
        return {f.name: (None, f) for f in fields(cls) if f.init}
    return {f.name: (g, f) for g, rec in groups.items() for f in fields(rec) if f.init}


def typed(cls: type, sec: Any, name: str, source: Path | str) -> Any:
    """Section ``name`` of the YAML (a mapping, or None for all defaults) as ``cls``; unknown
    keys, wrong kinds and values failing their check are one ConfigError each."""
    if sec is None:
        sec = {}
    if not isinstance(sec, dict):
        raise ConfigError(f"{source}: section {name!r} must be a mapping")
    known = keys(cls)
    values: dict[str, Any] = {}
    for key, raw in sec.items():
        f = known.get(key, (None, None))[1]
        if f is None:
            raise ConfigError(
                f"{source}: unknown key {name}.{key_text(key)}; known: {', '.join(known)}"
            )
        v = value(_kind(f.type), raw, f"{name}.{key}", source)
        check = f.metadata.get("check")
        if check is not None and not check(v):
            demand = f.metadata.get("demand") or "valid"
            raise ConfigError(f"{source}: {name}.{key} must be {demand}, got {shown(raw)}")
        values[key] = v
    try:
        groups = records(cls)
        if not groups:
            return cls(**values)
        parts = {
            g: rec(**{k: v for k, v in values.items() if known[k][0] == g})
            for g, rec in groups.items()
        }
        return cls(**parts)
    except ConfigError as exc:  # a check across keys in the class itself
        text = str(exc)
        raise ConfigError(text if text.startswith(f"{source}:") else f"{source}: {text}") from None
