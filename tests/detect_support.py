"""``monitor detect`` run as a user runs it (a subprocess on the tree under test), for the
tests that compare its events and summary."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any


def detect_cli(
    rec: Path, out_dir: Path, *extra: str, stem: str = "detect"
) -> tuple[int, dict[str, Any], str, list[dict[str, Any]]]:
    """``monitor detect REC --summary --events`` into ``out_dir`` (files named ``stem``):
    its exit code, summary, stderr and every event line (none when it wrote no events)."""
    summary, events = out_dir / f"{stem}.json", out_dir / f"{stem}.jsonl"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "monitor",
            "detect",
            str(rec),
            "--summary",
            str(summary),
            "--events",
            str(events),
            *extra,
        ],
        capture_output=True,
        text=True,
        check=False,
    )
    lines = [json.loads(x) for x in events.read_text().splitlines()] if events.exists() else []
    return proc.returncode, json.loads(summary.read_text()), proc.stderr, lines
