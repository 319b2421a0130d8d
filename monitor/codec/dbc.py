"""Loading the DBC: the shipped one or a user's file, always with cantools' strict checks."""

from __future__ import annotations

from pathlib import Path

import cantools
from cantools.database.can import Database

from monitor.errors import ConfigError
from monitor.resources import resource_path

DBC_NAME = "monitor.dbc"


def default_dbc_path() -> Path:
    """Path of the DBC shipped inside the package."""
    return resource_path("dbc", DBC_NAME)


def load_dbc(path: str | Path | None = None) -> Database:
    """Load ``path`` (default: the shipped DBC) with ``strict=True``.

    strict makes cantools refuse overlapping signals and signals outside the frame, which
    would otherwise decode silently wrong.  Any failure is a ``ConfigError`` naming the file.
    """
    dbc_path = Path(path) if path is not None else default_dbc_path()
    try:
        db = cantools.database.load_file(str(dbc_path), database_format="dbc", strict=True)
    except FileNotFoundError:
        raise ConfigError(f"{dbc_path}: DBC file not found") from None
    except OSError as exc:
        raise ConfigError(f"{dbc_path}: cannot read DBC file: {exc.strerror or exc}") from None
    except Exception as exc:  # cantools raises parser- and check-specific types
        reason = " ".join(str(exc).split()) or type(exc).__name__
        raise ConfigError(f"{dbc_path}: invalid DBC file: {reason}") from None
    if not isinstance(db, Database):  # pragma: no cover - database_format="dbc" gives CAN
        raise ConfigError(f"{dbc_path}: not a CAN database")
    return db
