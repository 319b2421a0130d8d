"""The documentation cannot drift from the commands: every `monitor <command>` it shows exists,
and the README keeps its two set-up commands."""

from __future__ import annotations

import re
import sys
from pathlib import Path

from monitor.cli import _subcommand_modules

REPO = Path(__file__).resolve().parents[1]
DOCS = [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]


def test_readme_keeps_the_two_set_up_commands() -> None:
    text = (REPO / "README.md").read_text()
    assert "    pip install . && monitor demo\n" in text
    assert "    pip install '.[test]' && python -m pytest -q -n auto --dist loadgroup\n" in text
    assert len(text.splitlines()) <= 150


def _code(text: str) -> str:
    """The code in a Markdown text: indented blocks and `spans` (where commands are shown)."""
    blocks = [x for x in text.splitlines() if x.startswith("    ")]
    return "\n".join(blocks + re.findall(r"`([^`]+)`", text))


def test_every_command_the_docs_show_exists() -> None:
    known = {m.replace("_", "-") for m in _subcommand_modules()}
    shown: dict[str, str] = {}
    for path in DOCS:
        for m in re.finditer(r"(?:^|[\s(`])monitor ([a-z][a-z0-9-]+)", _code(path.read_text())):
            shown.setdefault(m.group(1), str(path.relative_to(REPO)))
    unknown = {c: p for c, p in shown.items() if c not in known}
    assert not unknown, f"commands in the docs that `monitor` does not have: {unknown}"


def test_readme_links_point_at_files() -> None:
    text = (REPO / "README.md").read_text()
    for target in re.findall(r"\]\(([^)#]+)\)", text):
        assert (REPO / target).exists(), target


def test_frame_ids_the_docs_give_are_the_dbcs() -> None:
    """Every proprietary frame ID (PF 0xFF) written in the README or the docs is one the
    shipped DBCs define: a candump filter copied from the docs must show frames."""
    import cantools

    ids = {
        m.frame_id
        for name in ("monitor.dbc", "excavator4.dbc")
        for m in cantools.database.load_file(REPO / "dbc" / name).messages
    }
    masks = {0x1FFFFFFF, 0x1FFFFFF0}  # candump masks, not frames
    wrong = []
    for doc in DOCS:
        for token in re.findall(r"\b(?:0x)?([0-9A-Fa-f]{8})\b", doc.read_text()):
            frame_id = int(token, 16)
            if (frame_id >> 16) & 0xFF == 0xFF and frame_id not in masks | ids:
                wrong.append(f"{doc.relative_to(REPO)}: {token}")
    assert not wrong, wrong


def test_benchmarks_page_is_generated_from_its_records() -> None:
    """docs/benchmarks.md is built from the dated records in docs/benchmarks/: a figure added
    to the page by hand, or a record never rendered, fails here."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "benchmarks_page", REPO / "docs" / "hooks" / "benchmarks_page.py"
    )
    assert spec is not None and spec.loader is not None
    page = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = page  # dataclasses look their module up
    spec.loader.exec_module(page)
    records = [page.read_record(p) for p in sorted(page.RECORDS.glob("*.md"))]
    assert len(records) >= 50
    assert (REPO / "docs" / "benchmarks.md").read_text() == page.render(records), (
        "docs/benchmarks.md is out of date: run python docs/hooks/benchmarks_page.py"
    )
    # Each area shows its current figures on top, each figure whole (a record's single
    # string once came out one character per line).
    assert {r.area for r in records if r.current} == set(page.AREAS)
    assert all(len(f) > 3 for r in records for f in r.current)
