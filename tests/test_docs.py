"""The documentation cannot drift from the commands: every `monitor <command>` it shows exists,
and the README keeps its two set-up commands."""

from __future__ import annotations

import re
from pathlib import Path

from monitor.cli import _subcommand_modules

REPO = Path(__file__).resolve().parents[1]
DOCS = [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]


def test_readme_keeps_the_two_set_up_commands() -> None:
    text = (REPO / "README.md").read_text()
    assert "    pip install . && monitor demo\n" in text
    assert "    pip install '.[test]' && python -m pytest -q\n" in text
    assert len(text.splitlines()) <= 150


def test_every_command_the_docs_show_exists() -> None:
    known = {m.replace("_", "-") for m in _subcommand_modules()}
    shown: dict[str, str] = {}
    for path in DOCS:
        for m in re.finditer(r"\bmonitor ([a-z][a-z0-9-]+)", path.read_text()):
            shown.setdefault(m.group(1), str(path.relative_to(REPO)))
    # Words after "monitor" that are prose, not commands (e.g. "the monitor is inactive").
    prose = {"is", "on", "in", "to", "and", "the", "as", "at", "for", "with", "runs", "its",
             "gives", "goes", "says", "reads", "watches", "process", "daemon", "package",
             "sends", "writes", "keeps", "was", "has", "can", "itself", "must", "only", "would",
             "could", "needs", "of", "when", "from", "does", "will", "then", "or",
             "by"}  # fmt: skip
    unknown = {c: p for c, p in shown.items() if c not in known and c not in prose}
    assert not unknown, f"commands in the docs that `monitor` does not have: {unknown}"


def test_readme_links_point_at_files() -> None:
    text = (REPO / "README.md").read_text()
    for target in re.findall(r"\]\(([^)#]+)\)", text):
        assert (REPO / target).exists(), target
