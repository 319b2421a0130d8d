"""Package data: the DBC, the default configuration, shipped models and demo logs.

In the repository they live at the top level (dbc/, config/, replay/); the build maps
those folders to ``monitor.resources.<name>`` so an installed monitor finds them too.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

_KINDS = ("dbc", "config", "replay")


def resource_path(kind: str, name: str) -> Path:
    """Path of a shipped file, e.g. ``resource_path("dbc", "monitor.dbc")``."""
    if kind not in _KINDS:
        raise KeyError(f"unknown resource kind {kind!r}; expected one of {_KINDS}")
    checkout = Path(__file__).resolve().parents[2]
    if (checkout / "pyproject.toml").is_file() and (checkout / kind).is_dir():
        # Imported from a source checkout (a git worktree on PYTHONPATH, say): its own files,
        # not those of whichever checkout an editable install maps the resources to.
        return checkout / kind / name
    try:
        folder = Path(str(resources.files(f"monitor.resources.{kind}")))
    except ModuleNotFoundError:
        folder = checkout / kind
    return folder / name
