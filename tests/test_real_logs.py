"""``monitor detect`` on real car CAN logs: no hydraulic frames is a clear exit 3, never a
traceback; the two malformed logs are refused naming file and line (exit 2)."""

from __future__ import annotations

import re

import pytest
from shared_data import BAD_LOGS, TORN_LOGS
from shared_data import REAL_LOGS as LOGS

from monitor.cli import main

MALFORMED = {name for name, _ in BAD_LOGS}
TORN = dict(TORN_LOGS)

pytestmark = pytest.mark.skipif(
    not LOGS.is_dir(), reason=f"real CAN logs not available at {LOGS} (../shared is not cloned)"
)


def _logs() -> list[str]:
    return sorted(p.name for p in LOGS.glob("*.log")) if LOGS.is_dir() else []


@pytest.mark.parametrize("name", _logs())
def test_detect_on_real_car_logs(name, capsys):
    code = main(["detect", str(LOGS / name), "--j-every", "0"])
    err = capsys.readouterr().err.strip()
    if name in TORN:  # one warning line naming the torn line, then the result
        warning, err = err.split("\n", 1)
        assert f"{name}:{TORN[name]}: torn last line skipped" in warning
        assert warning.startswith("monitor detect: warning: ")
    assert "Traceback" not in err and len(err.splitlines()) == 1
    assert name in err
    if name in MALFORMED:
        assert code == 2
        assert re.search(rf"{re.escape(name)}:\d+:", err)  # file:line
    else:
        assert code == 3
        assert "hydraulic" in err
