"""Reading a configuration YAML strictly, before anything looks at its values.

* a size cap (a configuration is a few kB; a huge file is a mistake or an attack);
* no aliases or anchors (``&a`` / ``*a``): a 500-byte "billion laughs" would expand to
  gigabytes before any check could run, and no configuration of ours needs them;
* no duplicate keys: YAML keeps the last one silently, so a key given twice is almost always
  an edit gone wrong;
* errors name the file and the line, never the whole input.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import Any

import yaml

from monitor.errors import ConfigError

MAX_BYTES = 1_000_000
MAX_DEPTH = 32  # a configuration nests two or three levels


class _StrictLoader(yaml.SafeLoader):
    """SafeLoader that refuses aliases and duplicate mapping keys."""

    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise _Refused(
                f"line {event.start_mark.line + 1}: YAML aliases (*name) are not "
                "allowed in a configuration"
            )
        # PyYAML composes recursively: 5,000 nested brackets would end in a RecursionError.
        self._depth = getattr(self, "_depth", 0) + 1
        try:
            if self._depth > MAX_DEPTH:
                line = self.peek_event().start_mark.line + 1
                raise _Refused(f"line {line}: nested deeper than {MAX_DEPTH} levels")
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_mapping(self, node: Any, deep: bool = False) -> Any:
        seen: set[Any] = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            if key in seen:
                raise _Refused(
                    f"line {key_node.start_mark.line + 1}: key {str(key)[:40]!r} is given twice"
                )
            seen.add(key)
        return super().construct_mapping(node, deep)

    def construct_yaml_int(self, node: Any) -> Any:
        try:
            return super().construct_yaml_int(node)
        except ValueError:  # more digits than Python converts (4,300): a ValueError traceback
            raise _Refused(
                f"line {node.start_mark.line + 1}: an integer of "
                f"{len(node.value)} characters is not a number a configuration "
                "holds"
            ) from None


_StrictLoader.add_constructor("tag:yaml.org,2002:int", _StrictLoader.construct_yaml_int)


class _Refused(Exception):
    pass


def _read_text(path: Path, what: str) -> str:
    """The file's text; a FIFO, a device or a directory is refused without blocking (a FIFO
    at the config's path hung ``monitor run`` at start and at every SIGHUP)."""
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    with os.fdopen(fd, "rb") as fh:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise ConfigError(
                f"{path}: not a regular file (a FIFO, device or directory); a {what} must be a file"
            )
        if st.st_size > MAX_BYTES:
            raise ConfigError(
                f"{path}: {st.st_size} bytes is too large for a {what} (at most {MAX_BYTES})"
            )
        data = fh.read(MAX_BYTES + 1)
    if len(data) > MAX_BYTES:  # grew since the stat
        raise ConfigError(f"{path}: too large for a {what} (at most {MAX_BYTES} bytes)")
    return data.decode("utf-8")


def read_yaml(path: Path, what: str) -> Any:
    """The parsed YAML of ``path`` (``what``: "config", "simulator config" for messages)."""
    try:
        text = _read_text(path, what)
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read {what}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not a text file (UTF-8 expected)") from None
    try:
        return yaml.load(text, Loader=_StrictLoader)  # noqa: S506 - a SafeLoader subclass
    except _Refused as exc:
        raise ConfigError(f"{path}: {exc}") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}: " if mark is not None else ""
        problem = getattr(exc, "problem", None) or "not valid YAML"
        raise ConfigError(f"{path}: {where}{problem}") from None
