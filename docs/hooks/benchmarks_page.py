"""docs/benchmarks.md from the dated records in docs/benchmarks/ (run it after adding one).

Each record is one measurement: a Markdown file named ``YYYY-MM-DD-slug.md`` whose YAML front
matter holds ``title``, ``date``, ``area`` (one of ``AREAS``), optionally ``time`` (HH:MM, to
order records of one day), ``command`` (what reproduces it) and ``current`` (the headline
figures, for the records whose figures are the current ones), followed by the data and what
it means. The page puts the current figures on top, then every record by area, newest first.

    python docs/hooks/benchmarks_page.py          # rewrite docs/benchmarks.md
    python docs/hooks/benchmarks_page.py --check  # exit 1 when the page is out of date (CI)
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import yaml

DOCS = Path(__file__).resolve().parents[1]
RECORDS = DOCS / "benchmarks"
PAGE = DOCS / "benchmarks.md"

#: Area key -> its section heading on the page, in page order.
AREAS = {
    "detection": "Detection on the simulator (`monitor eval-sim`)",
    "rig": "Detection on a real rig: ZeMA hydraulic test rig (`monitor eval-uci`)",
    "fleet": "Commissioning and the fleet (`monitor fleet`)",
    "gap": "Sim-to-real diagnosis (`monitor gap`)",
    "performance": "Performance (`monitor bench`, `pytest benchmarks`)",
    "controller": "Target hardware and controller footprint",
}

_INTRO = """\
# Benchmarks and evaluations

Dated measurements, each with the command that reproduces it. Figures on this page come from
the project's 2-core x86-64 development machine (Python 3.11, numba 0.68), which other jobs
share: wall-clock figures carry the load average when it mattered; ratios are measured side
by side in one run. Explanations of what is measured live under Explanation.

This page is generated from the records in `docs/benchmarks/` (one file a measurement) by
`python docs/hooks/benchmarks_page.py`; add a record there, never edit this page.
"""


@dataclass(frozen=True)
class Record:
    name: str
    title: str
    date: str
    time: str
    area: str
    command: str | None
    current: tuple[str, ...]
    body: str


def read_record(path: Path) -> Record:
    text = path.read_text(encoding="utf-8")
    if not text.startswith("---\n"):
        raise ValueError(f"{path}: no front matter (a first line '---')")
    head, _, body = text[4:].partition("\n---\n")
    meta = yaml.safe_load(head) or {}
    missing = {"title", "date", "area"} - set(meta)
    if missing:
        raise ValueError(f"{path}: front matter lacks {sorted(missing)}")
    if meta["area"] not in AREAS:
        raise ValueError(f"{path}: area {meta['area']!r} is not one of {list(AREAS)}")
    if not path.name.startswith(str(meta["date"])):
        raise ValueError(f"{path}: the file name must start with its date {meta['date']}")
    return Record(
        name=path.name,
        title=str(meta["title"]),
        date=str(meta["date"]),
        time=str(meta.get("time", "12:00")),
        area=str(meta["area"]),
        command=meta.get("command"),
        current=_figures(meta.get("current")),
        body=body.strip(),
    )


def _figures(current: object) -> tuple[str, ...]:
    """``current`` as its figures: one string is one figure (not one per character)."""
    if not current:
        return ()
    if isinstance(current, str):
        return (current,)
    if isinstance(current, list):
        return tuple(str(c) for c in current)
    raise ValueError(f"current must be a string or a list of strings, got {current!r}")


def _dated(r: Record) -> str:
    return r.title if r.date in r.title else f"{r.title} ({r.date})"


def render(records: list[Record]) -> str:
    newest_first = sorted(records, key=lambda r: (r.date, r.time, r.title), reverse=True)
    out = [_INTRO, "## Current figures", "", "| area | figures | measured in |", "|---|---|---|"]
    for area, heading in AREAS.items():
        for r in newest_first:
            if r.area == area and r.current:
                figures = "<br>".join(r.current)
                out.append(f"| {heading} | {figures} | {_dated(r)} |")
    out.append("")
    for area, heading in AREAS.items():
        out += [f"## {heading}", ""]
        for r in (r for r in newest_first if r.area == area):
            out += [f"### {_dated(r)}", ""]
            if r.command:
                out += ["    " + line if line else "" for line in r.command.splitlines()]
                out.append("")
            out += [r.body, ""]
    return "\n".join(out).rstrip() + "\n"


def main(argv: list[str]) -> int:
    records = [read_record(p) for p in sorted(RECORDS.glob("*.md"))]
    page = render(records)
    if "--check" in argv:
        if PAGE.read_text(encoding="utf-8") != page:
            print(f"{PAGE} is out of date: run python docs/hooks/benchmarks_page.py")
            return 1
        return 0
    PAGE.write_text(page, encoding="utf-8")
    print(f"{PAGE}: {len(records)} records")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
