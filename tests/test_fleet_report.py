"""Health index, prognosis and the fleet page from a logs.parquet written by hand."""

from __future__ import annotations

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from monitor.cli import main
from monitor.fleet.health import prognosis
from monitor.fleet.store import LOG_SCHEMA


def _row(machine: str, i: int, ratio: float | None, **kw) -> dict:
    r = {name: None for name in LOG_SCHEMA.names}
    p95 = None if ratio is None else ratio * 0.8
    r |= {"machine": machine, "log": f"{machine}/logs/day{i:02d}.log", "sha256": f"{i}",
          "verdict": "healthy", "alarm": False, "sensor_fault": False, "max_j_ratio": ratio,
          "p95_j_ratio": p95, "model": "commissioned"}  # fmt: skip
    return r | kw


def test_a_straight_rise_crosses_where_the_line_does():
    # 0.4, 0.5, ... rises 0.1 a log and is 0.7 at the newest: 1.0 in 3 more logs.
    rows = [_row("A", i, 0.4 + 0.1 * i) for i in range(4)]
    p = prognosis("A", rows)
    assert p.slope_per_log == pytest.approx(0.1)
    assert p.logs_to_alarm == pytest.approx(3.0)
    lo, hi = p.logs_to_alarm_range
    assert lo == pytest.approx(3.0) and hi == pytest.approx(3.0)  # exact line: no spread


def test_flat_or_falling_is_no_upward_trend_and_unjudged_logs_are_left_out():
    rows = [_row("B", i, r) for i, r in enumerate([0.5, 0.5, None, 0.4, 0.45, 0.3])]
    p = prognosis("B", rows)
    assert p.logs == 5 and p.logs_to_alarm is None and p.text == "no upward trend"
    assert prognosis("C", rows[:2]).text == "too few judged logs"


def test_report_writes_the_page_and_its_pictures(tmp_path):
    rows = [_row("M01", i, 0.4 + 0.1 * i) for i in range(4)]
    rows += [_row("M02", i, 0.3) for i in range(4)]
    rows += [_row("M03", 1, None, verdict="not_judged", error="unreadable: Permission denied")]
    pq.write_table(pa.Table.from_pylist(rows, LOG_SCHEMA), tmp_path / "logs.parquet")
    out = tmp_path / "page"
    assert main(["fleet", "report", str(tmp_path), "--out", str(out)]) == 0
    page = (out / "fleet.md").read_text()
    assert "| M01 | 4 | healthy | 0.70 | +0.100 | 3.0 logs" in page
    assert "| M02 | 4 | healthy | 0.30 | +0.000 | no upward trend" in page
    assert "M03/logs/day01.log`: unreadable: Permission denied" in page
    for png in ("health.png", "timeline.png"):
        assert (out / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_report_without_results_is_one_line_and_exit_2(tmp_path, capsys):
    assert main(["fleet", "report", str(tmp_path), "--out", str(tmp_path / "p")]) != 0
    assert "logs.parquet: no such file" in capsys.readouterr().err
