"""deploy/: the systemd unit passes ``systemd-analyze verify`` (offline: no running systemd
needed), with no warning at all (verify exits 0 even on unknown keys, so its output counts)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest
from live_support import REPO

UNIT = REPO / "deploy" / "hydraulic-monitor.service"


@pytest.mark.skipif(
    shutil.which("systemd-analyze") is None, reason="no systemd-analyze (apt package systemd)"
)
def test_unit_verifies_cleanly(tmp_path: Path) -> None:
    monitor = shutil.which("monitor")
    if monitor is None:
        pytest.skip("`monitor` is not installed on PATH (pip install .)")
    # verify checks that ExecStart's program exists: point it at this machine's install.
    text = UNIT.read_text()
    assert "ExecStart=/usr/local/bin/monitor run" in text
    unit = tmp_path / UNIT.name
    unit.write_text(text.replace("ExecStart=/usr/local/bin/monitor", f"ExecStart={monitor}"))
    out = subprocess.run(
        ["systemd-analyze", "verify", str(unit)], capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0 and not (out.stdout + out.stderr).strip(), out.stdout + out.stderr
