"""mkdocs hook: reference tables generated from the code, so the docs cannot drift from it.

A page asks for a table with a marker line; the hook replaces it when the site is built:

    <!-- generated: cli -->      every `monitor` subcommand's --help (argparse)
    <!-- generated: config -->   every config/monitor.yaml key (the settings dataclasses)
    <!-- generated: dbc -->      the frames and signals of dbc/monitor.dbc (cantools)
    <!-- generated: dtc -->      the default J1939 SPN/FMI of each fault and sensor
    <!-- generated: errors -->   the error classes and their exit codes
    <!-- generated: actions -->  the fleet page's action text per fault and sensor check
"""

from __future__ import annotations

import dataclasses
import inspect
import io
import re
import sys
from contextlib import redirect_stdout, suppress
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))  # the checkout's package, installed or not

_MARKER = re.compile(r"^<!-- generated: (\w+) -->$", re.M)


def on_page_markdown(markdown: str, **_: Any) -> str:
    return _MARKER.sub(lambda m: _GENERATORS[m.group(1)](), markdown)


def _cli() -> str:
    from monitor.cli import _subcommand_modules, build_parser

    out = ["```text", _help(build_parser(), []), "```"]
    for name in _subcommand_modules():
        cmd = name.replace("_", "-")
        parser = build_parser(name)
        out += [f"## monitor {cmd}", "", "```text", _help(parser, [cmd]), "```", ""]
    return "\n".join(out)


def _help(parser: Any, argv: list[str]) -> str:
    buf = io.StringIO()
    with redirect_stdout(buf), suppress(SystemExit):
        parser.parse_args([*argv, "--help"])
    return buf.getvalue().rstrip()


# ``name: type = default  # comment`` in a dataclass body: the comment documents the field.
_FIELD_LINE = re.compile(r"^\s+(\w+)\s*:[^#]*?(?:#\s*(.*))?$")


def _field_comments(cls: type) -> dict[str, str]:
    comments: dict[str, str] = {}
    for line in inspect.getsource(cls).splitlines():
        m = _FIELD_LINE.match(line)
        if m and m.group(2):
            comments[m.group(1)] = m.group(2).strip()
    return comments


def _default(f: dataclasses.Field) -> str:
    if f.default is not dataclasses.MISSING:
        value = f.default
    elif f.default_factory is not dataclasses.MISSING:
        value = f.default_factory()
    else:
        return "(required)"
    return "" if dataclasses.is_dataclass(value) else f"`{value!r}`"


def _config() -> str:
    from monitor.schema.sections import keys, records

    try:
        from monitor.config.settings import MonitorConfig
    except ImportError:  # the layout before the packages
        from monitor.config import MonitorConfig  # type: ignore[no-redef]

    from monitor.config.settings import _TOP_KEYS

    def sections(cls: type) -> list[tuple[str, type]]:
        """(YAML section, its class); a record of sections (``gating``) gives each of its."""
        out = []
        for f in dataclasses.fields(cls):
            default = f.default_factory if f.default_factory is not dataclasses.MISSING else None
            value = default() if callable(default) else None
            if not dataclasses.is_dataclass(value):
                continue
            if f.name not in _TOP_KEYS and records(type(value)):
                out += sections(type(value))
            else:
                out.append((f.name, type(value)))
        return out

    out = []
    for name, cls in sections(MonitorConfig):
        doc = inspect.getdoc(cls) or ""
        # A section made of records (one per check) keeps its YAML keys flat.
        groups = records(cls)
        comments = _field_comments(cls)
        for rec in groups.values():
            comments.update(_field_comments(rec))
        out += [
            f"## `{name}`",
            "",
            doc.split("\n\n")[0],
            "",
            "| key | type | default | meaning |",
            "|---|---|---|---|",
        ]
        for _, f in keys(cls).values():
            meaning = f.metadata.get("doc") or comments.get(f.name, "")
            unit = f.metadata.get("unit")
            if unit:
                meaning = f"{meaning} [{unit}]".strip()
            kind = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", str(f.type))
            out.append(f"| `{f.name}` | `{kind}` | {_default(f)} | {meaning} |")
        out.append("")
    return "\n".join(out)


def _dbc() -> str:
    import cantools

    out = []
    for dbc in sorted((REPO / "dbc").glob("*.dbc")):
        db = cantools.database.load_file(str(dbc))
        header = "| frame ID | message | cycle | signals (unit, range) |"
        out += [f"## `dbc/{dbc.name}`", "", header, "|---|---|---|---|"]
        for m in sorted(db.messages, key=lambda m: m.frame_id):
            width = 8 if m.is_extended_frame else 3
            cycle = f"{m.cycle_time} ms" if m.cycle_time else "on event"
            sigs = ", ".join(
                f"{s.name} ({s.unit or '-'}, {s.minimum:g}..{s.maximum:g})"
                if s.minimum is not None and s.maximum is not None
                else f"{s.name} ({s.unit or '-'})"
                for s in m.signals
            )
            out.append(f"| `{m.frame_id:0{width}X}` | {m.name} | {cycle} | {sigs} |")
        out.append("")
    return "\n".join(out)


def _dtc() -> str:
    from monitor.codec.j1939 import dtc

    out = ["| what | default SPN | FMI |", "|---|---|---|"]
    for name, spn in dtc.DEFAULT_FAULT_SPN.items():
        out.append(f"| hydraulic fault `{name}` | {spn} | {dtc.DEFAULT_FAULT_FMI[name]} |")
    for name, spn in dtc.DEFAULT_SENSOR_SPN.items():
        out.append(f"| sensor `{name}` stale | {spn} | {dtc.DEFAULT_SENSOR_FMI} |")
    for check, fmi in dtc.DEFAULT_CHECK_FMI.items():
        out.append(f"| sensor named by the `{check}` check | the sensor's SPN | {fmi} |")
    return "\n".join(out)


def _errors() -> str:
    from monitor import errors

    out = ["| error | exit code | when |", "|---|---|---|"]
    for name, cls in inspect.getmembers(errors, inspect.isclass):
        if issubclass(cls, errors.MonitorError):
            doc = (inspect.getdoc(cls) or "").split("\n")[0]
            out.append(f"| `{name}` | {cls.exit_code} | {doc} |")
    return "\n".join(out)


def _actions() -> str:
    from monitor.fleet.actions import markdown_table

    return markdown_table()


_GENERATORS = {
    "cli": _cli,
    "config": _config,
    "dbc": _dbc,
    "dtc": _dtc,
    "errors": _errors,
    "actions": _actions,
}
