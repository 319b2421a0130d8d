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
    r |= {
        "machine": machine,
        "log": f"{machine}/logs/day{i:02d}.log",
        "sha256": f"{i}",
        "verdict": "healthy",
        "alarm": False,
        "sensor_fault": False,
        "max_j_ratio": ratio,
        "p95_j_ratio": p95,
        "model": "commissioned",
    }
    return r | kw


def test_a_straight_rise_crosses_where_the_line_does():
    # 0.4, 0.5, ... rises 0.1 a log and is 0.7 at the newest: 1.0 in 3 more logs.
    rows = [_row("A", i, 0.4 + 0.1 * i) for i in range(4)]
    p = prognosis("A", rows)
    assert p.slope_per_log == pytest.approx(0.1)
    assert p.logs_to_alarm == pytest.approx(3.0)
    lo, hi = p.logs_to_alarm_range
    assert lo == pytest.approx(3.0) and hi == pytest.approx(3.0)  # exact line: no spread


def test_a_rise_that_scatter_explains_is_no_trend_and_four_straight_rises_are():
    # Kendall's tau, one-sided, by hand: n logs all rising happen by chance 1 in n! times
    # (3 logs: 1/6 = 0.17, above 0.10: no trend; 4 logs: 1/24 = 0.042: a trend).
    three = prognosis("A", [_row("A", i, 0.4 + 0.1 * i) for i in range(3)])
    assert three.logs_to_alarm is None and three.p_value == pytest.approx(1 / 6)
    assert three.text == "no clear upward trend (p 0.17)"
    four = prognosis("A", [_row("A", i, 0.4 + 0.1 * i) for i in range(4)])
    assert four.p_value == pytest.approx(1 / 24) and four.logs_to_alarm == pytest.approx(3.0)
    # Rising but with one log out of order (5 of 6 pairs concordant): p = 4/24 = 0.17.
    noisy = prognosis("A", [_row("A", i, r) for i, r in enumerate([0.4, 0.6, 0.5, 0.7])])
    assert noisy.logs_to_alarm is None and noisy.p_value == pytest.approx(4 / 24)


def test_a_trend_already_at_one_below_the_alarm_is_due_now():
    # 0.2, 0.5, 0.8, 0.98: pairwise slopes 0.3, 0.3, 0.26, 0.3, 0.24, 0.18, median 0.28;
    # scipy's intercept median(y) - slope * median(x) = 0.65 - 0.42 = 0.23, so the line is at
    # 0.23 + 3 * 0.28 = 1.07 at the last log, whose own level (0.98) has not alarmed.
    p = prognosis("A", [_row("A", i, r) for i, r in enumerate([0.2, 0.5, 0.8, 0.98])])
    assert p.slope_per_log == pytest.approx(0.28)
    assert p.logs_to_alarm == pytest.approx((1.0 - 1.07) / 0.28)
    assert p.text == "due now (the trend line is at or above 1.0)"


def test_a_machine_whose_last_log_alarmed_is_at_or_above_one_whatever_the_trend():
    p = prognosis("A", [_row("A", i, r) for i, r in enumerate([0.3, 4.6, 2.0])])
    assert p.text == "at or above 1.0"


def test_flat_or_falling_is_no_upward_trend_and_unjudged_logs_are_left_out():
    rows = [_row("B", i, r) for i, r in enumerate([0.5, 0.5, None, 0.4, 0.45, 0.3])]
    p = prognosis("B", rows)
    assert p.logs == 5 and p.logs_to_alarm is None and p.text == "no upward trend"
    assert prognosis("C", rows[:2]).text == "too few judged logs"


def test_slight_wear_is_trended_on_the_typical_level_not_on_the_scattered_peak():
    # The peak (max J / eps0) scatters with the manoeuvres of each log: alone it is no trend
    # (9 of 15 pairs concordant, Kendall p 0.36).  The median rises 0.02 a log.
    peak = [0.6, 0.3, 0.7, 0.4, 0.8, 0.5]
    mid = [0.10, 0.12, 0.14, 0.16, 0.18, 0.20]
    alone = prognosis("A", [_row("A", i, m) for i, m in enumerate(peak)])
    assert alone.logs_to_alarm is None and alone.basis == "peak"
    rows = [_row("A", i, m, p50_j_ratio=q) for i, (m, q) in enumerate(zip(peak, mid, strict=True))]
    p = prognosis("A", rows)
    # Peak-to-typical ratios 6, 2.5, 5, 2.5, 4.44, 2.5: median (2.5 + 4.444) / 2 = 3.472.
    ratio = (2.5 + 0.8 / 0.18) / 2
    assert p.basis == "typical" and p.p_value == pytest.approx(1 / 720)  # 6 straight rises
    assert p.slope_per_log == pytest.approx(0.02 * ratio)
    assert p.logs_to_alarm == pytest.approx((1.0 - 0.20 * ratio) / (0.02 * ratio))
    assert p.last_index == 0.5  # the page still shows the newest log's peak


def test_a_healthy_machine_with_a_steady_typical_level_has_no_trend_however_its_peak_jumps():
    peak = [0.2, 0.3, 0.45, 0.6, 0.7, 0.9]  # six straight rises of the peak ...
    mid = [0.12, 0.10, 0.13, 0.11, 0.12, 0.10]  # ... while the typical level stays put
    rows = [_row("A", i, m, p50_j_ratio=q) for i, (m, q) in enumerate(zip(peak, mid, strict=True))]
    p = prognosis("A", rows)
    assert p.basis == "typical" and p.logs_to_alarm is None
    assert prognosis("A", [_row("A", i, m) for i, m in enumerate(peak)]).logs_to_alarm is not None


def test_report_writes_the_page_and_its_pictures(tmp_path):
    rows = [_row("M01", i, 0.4 + 0.1 * i) for i in range(4)]
    rows += [_row("M02", i, 0.3) for i in range(4)]
    rows += [_row("M03", 1, None, verdict="not_judged", error="unreadable: Permission denied")]
    pq.write_table(pa.Table.from_pylist(rows, LOG_SCHEMA), tmp_path / "logs.parquet")
    out = tmp_path / "page"
    assert main(["fleet", "report", str(tmp_path), "--out", str(out)]) == 0
    page = (out / "fleet.md").read_text()
    assert "| M01 | 4 | healthy | 0.70 | - | +0.100 | 3.0 logs" in page
    assert "| M02 | 4 | healthy | 0.30 | - | +0.000 | no upward trend" in page
    assert "M03/logs/day01.log`: unreadable: Permission denied" in page
    for png in ("health.png", "timeline.png"):
        assert (out / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # Results without drifts (written before the column): no empty drift picture.
    assert not (out / "drift.png").exists() and "drift.png" not in page


def test_drift_is_the_median_of_the_last_three_logs_and_flagged_from_three(tmp_path):
    # M01: drifts 1.0, 1.2, 5.0, 4.0, 2.9 -> median of the last three (5.0, 4.0, 2.9) is 4.0,
    # at or above 3: flagged.  M02: 0.9, 3.5, 1.1 -> 1.1, not flagged (one odd log is not a
    # drift).  M03: results from before the column: "-".
    rows = [_row("M01", i, 0.3, p50_j_drift=d) for i, d in enumerate([1.0, 1.2, 5.0, 4.0, 2.9])]
    rows += [_row("M02", i, 0.3, p50_j_drift=d) for i, d in enumerate([0.9, 3.5, 1.1])]
    rows += [_row("M03", i, 0.3) for i in range(3)]
    pq.write_table(pa.Table.from_pylist(rows, LOG_SCHEMA), tmp_path / "logs.parquet")
    assert main(["fleet", "report", str(tmp_path), "--out", str(tmp_path / "page")]) == 0
    page = (tmp_path / "page" / "fleet.md").read_text()
    assert "| M01 | 5 | healthy | 0.30 | 4.0 x (wearing?) |" in page
    assert "| M02 | 3 | healthy | 0.30 | 1.1 x |" in page
    assert "| M03 | 3 | healthy | 0.30 | - |" in page
    assert "![drift from commissioning](drift.png)" in page
    assert (tmp_path / "page" / "drift.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_report_without_results_is_one_line_and_exit_2(tmp_path, capsys):
    assert main(["fleet", "report", str(tmp_path), "--out", str(tmp_path / "p")]) != 0
    assert "logs.parquet: no such file" in capsys.readouterr().err
