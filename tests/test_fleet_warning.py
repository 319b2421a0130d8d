"""The first warning: the prognosis replayed log by log, against the machine's first alarm.

Rows are written by hand with a typical level (median J / eps0) and a peak exactly twice it,
so the trended level (typical x the median peak-to-typical ratio, 2) is ``level`` below.
Four logs a day, named as ``monitor simulate-fleet`` names them (day01-1 ... day01-4, ...).
"""

from __future__ import annotations

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from monitor.cli import main
from monitor.fleet.health import first_warning, replay
from monitor.fleet.store import LOG_SCHEMA


def _rows(machine: str, levels: list[float], alarm_from: int | None = None) -> list[dict]:
    """One row per level; ``alarm_from``: the 1-based log from which every log alarms."""
    out = []
    for i, level in enumerate(levels):
        alarm = alarm_from is not None and i + 1 >= alarm_from
        r = {name: None for name in LOG_SCHEMA.names}
        r |= {
            "machine": machine,
            "log": f"{machine}/logs/day{i // 4 + 1:02d}-{i % 4 + 1}.log",
            "sha256": f"{i}",
            "verdict": "fault" if alarm else "healthy",
            "alarm": alarm,
            "sensor_fault": False,
            "max_j_ratio": level,
            "p50_j_ratio": level / 2,
            "model": "commissioned",
        }
        out.append(r)
    return out


# 0.25 + 0.05 a log: 1.0 at the 16th log (day04-4), where the machine alarms.
RISE = [0.25 + 0.05 * i for i in range(20)]


def test_a_straight_rise_warns_at_the_fourth_log_and_forecasts_the_alarm_log():
    # Logs 1-2: too few for a fit.  Log 3: three straight rises happen by chance 1 in 3! =
    # 0.17 (Kendall, one-sided), not below 0.10: no trend.  Log 4: 1 in 4! = 0.042, a trend;
    # the line is exact (slope 0.05, every pairwise slope 0.05, so the interval is a point)
    # and at 0.40 on log 4: (1.0 - 0.40) / 0.05 = 12 logs, i.e. log 16, which is where the
    # alarm comes: 12 logs and 3 days (day01 -> day04) of lead.
    rows = _rows("A", RISE, alarm_from=16)
    progs = replay("A", rows)
    assert [p.logs_to_alarm for p in progs[:3]] == [None, None, None]
    assert progs[2].p_value == pytest.approx(1 / 6)
    w = first_warning("A", rows)
    assert (w.warning_log, w.warning_name) == (4, "day01-4")
    assert w.forecast.p_value == pytest.approx(1 / 24)
    assert w.forecast.slope_per_log == pytest.approx(0.05)
    assert w.forecast.logs_to_alarm == pytest.approx(12.0)
    assert w.forecast.logs_to_alarm_range == pytest.approx((12.0, 12.0))
    assert (w.alarm_log, w.alarm_name, w.lead_logs, w.lead_days) == (16, "day04-4", 12, 3)
    assert w.text == (
        "log 4 (day01-4): crossing in 12.0 logs (12..12); alarm at log 16 "
        "(day04-4), 12 logs, 3 d later"
    )


def test_a_dip_before_the_rise_warns_once_the_forecast_is_bounded():
    # 0.50, 0.41, 0.32, then +0.04 a log.  Logs 4-6: the median pairwise slope is negative
    # (-0.068, -0.025, -0.0033 by hand): no upward trend.  Log 7 fits logs 2-7 (0.41, 0.32,
    # 0.36, 0.40, 0.44, 0.48): of the 15 pairs 3 are falling (0.41 before 0.32, 0.36, 0.40),
    # Kendall's exact one-sided p is the share of orderings of 6 with at most 3 inversions,
    # (1 + 5 + 14 + 29) / 720 = 0.068 < 0.10: a trend.  Slopes sorted: -0.09, -0.025,
    # -0.0033, 0.0075, 0.014, then ten of 0.04: median 0.04.  Intercept median(y) - 0.04 x
    # median(x) = 0.405 - 0.1 = 0.305, so 0.505 at log 7 and (1 - 0.505) / 0.04 = 12.375
    # logs.  Sen's 90 % bounds are the sorted slopes at (15 -+ 1.645 x sqrt(6 x 5 x 17 / 18))
    # / 2, rounded (minus one for the lower): indices 2 and 12, -0.0033 and 0.04: the far
    # end is unbounded, so no warning yet.  Log 8 fits logs 3-8, a straight line of 0.04 a
    # log: every slope 0.04, the interval a point, 0.52 at log 8, (1 - 0.52) / 0.04 = 12
    # logs: the warning.  The alarm at log 10 (day03-2) comes 2 logs and 1 day later.
    levels = [0.50, 0.41, 0.32, 0.36, 0.40, 0.44, 0.48, 0.52, 0.56, 1.1]
    rows = _rows("V", levels, alarm_from=10)
    progs = replay("V", rows)
    assert all(p.slope_per_log < 0 for p in progs[3:6])
    seven = progs[6]
    assert seven.p_value == pytest.approx(49 / 720)
    assert seven.slope_per_log == pytest.approx(0.04)
    assert seven.level_now == pytest.approx(0.505)
    assert seven.logs_to_alarm == pytest.approx(12.375)
    assert seven.logs_to_alarm_range == pytest.approx((12.375, float("inf")))
    w = first_warning("V", rows)
    assert (w.warning_log, w.warning_name) == (8, "day02-4")
    assert w.forecast.logs_to_alarm == pytest.approx(12.0)
    assert w.forecast.logs_to_alarm_range == pytest.approx((12.0, 12.0))
    assert (w.alarm_log, w.lead_logs, w.lead_days) == (10, 2, 1)
    assert w.text.startswith("log 8 (day02-4): crossing in 12.0 logs (12..12); alarm")


def test_a_machine_that_alarms_at_its_first_log_has_no_warning_whatever_follows():
    # The same straight rise after the alarm would give a crossing from log 4 on: a forecast
    # made once the machine has alarmed is no warning.
    rows = _rows("B", RISE[:8], alarm_from=1)
    assert replay("B", rows)[3].logs_to_alarm is not None
    w = first_warning("B", rows)
    assert (w.warning_log, w.forecast, w.alarm_log, w.lead_logs) == (None, None, 1, None)
    assert w.text == "no warning before the alarm at log 1 (day01-1)"


def test_a_warning_that_has_not_been_followed_by_an_alarm_says_so():
    w = first_warning("A", _rows("A", RISE[:10]))
    assert (w.warning_log, w.alarm_log, w.lead_logs, w.lead_days) == (4, None, None, None)
    assert w.text == "log 4 (day01-4): crossing in 12.0 logs (12..12); no alarm yet"


def test_a_flat_healthy_machine_neither_warns_nor_alarms():
    w = first_warning("C", _rows("C", [0.3] * 12))
    assert (w.warning_log, w.alarm_log) == (None, None) and w.text == "-"


def test_logs_are_counted_as_the_page_counts_them_unjudged_ones_included_and_days_optional():
    # An unreadable log between logs 2 and 3 of the straight rise: the fit skips it, so the
    # fourth *judged* log (now the fifth log) warns; the page's log numbers count every row.
    rows = _rows("A", RISE[:6])
    bad = rows[0] | {
        "log": "A/logs/x.log",
        "sha256": "bad",
        "max_j_ratio": None,
        "p50_j_ratio": None,
        "verdict": "not_judged",
        "error": "unreadable",
    }
    rows = [*rows[:2], bad, *rows[2:]]
    for r in rows:  # names without a day: no lead in days
        r["log"] = r["log"].replace("/day", "/run")
    rows[-1] |= {"alarm": True}
    w = first_warning("A", rows)
    assert (w.warning_log, w.warning_name, w.alarm_log) == (5, "run01-4", 7)
    assert (w.lead_logs, w.lead_days) == (2, None)
    assert w.text.endswith("alarm at log 7 (run02-2), 2 logs later")


def test_the_page_has_the_first_warning_column(tmp_path):
    rows = _rows("M01", RISE, alarm_from=16) + _rows("M02", [0.3] * 20)
    rows += _rows("M03", RISE[:8], alarm_from=1)
    pq.write_table(pa.Table.from_pylist(rows, LOG_SCHEMA), tmp_path / "logs.parquet")
    out = tmp_path / "page"
    assert main(["fleet", "report", str(tmp_path), "--out", str(out)]) == 0
    page = (out / "fleet.md").read_text()
    assert "| predicted crossing of 1.0 | first warning | alarms |" in page
    assert (
        "| at or above 1.0 | log 4 (day01-4): crossing in 12.0 logs (12..12); alarm at "
        "log 16 (day04-4), 12 logs, 3 d later | 5 |"
    ) in page
    assert "| no upward trend | - | 0 |" in page
    assert "| no warning before the alarm at log 1 (day01-1) | 8 |" in page
    assert (out / "health.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _with_drift(rows: list[dict], drifts: list[float | None]) -> list[dict]:
    for r, d in zip(rows, drifts, strict=True):
        r["p50_j_drift"] = d
    return rows


def test_a_commissioned_machine_warns_when_its_drift_reaches_two():
    # Drift at a log = median of the last three logs' p50_j_drift: logs 1-4 give 1.0, 1.05,
    # 1.1, 1.2 (median of 1.1, 1.2, 2.5); log 5 the median of 1.2, 2.5, 2.6 = 2.5 >= 2: the
    # warning, 3 logs and 0 days (day02-1 -> day02-4) before the alarm at log 8.
    drifts = [1.0, 1.1, 1.2, 2.5, 2.6, 2.7, 3.0, 3.2]
    rows = _with_drift(_rows("D", [0.4] * 8, alarm_from=8), drifts)
    w = first_warning("D", rows)
    assert (w.warning_log, w.warning_name, w.forecast) == (5, "day02-1", None)
    assert w.drift == pytest.approx(2.5)
    assert (w.alarm_log, w.lead_logs, w.lead_days) == (8, 3, 0)
    assert w.text == "log 5 (day02-1): drift 2.5 x; alarm at log 8 (day02-4), 3 logs, 0 d later"


def test_one_odd_log_does_not_warn_and_a_commissioned_machine_is_not_warned_by_its_trend():
    # One log at 5 x among logs at 1 x: every median of three is 1.0.  The level rises
    # straight (the forecast alone would warn at log 4, first test above), but a machine
    # with a drift is warned by its drift only.
    drifts = [1.0, 1.0, 5.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0]
    w = first_warning("E", _with_drift(_rows("E", RISE[:10]), drifts))
    assert (w.warning_log, w.drift, w.text) == (None, None, "-")


def test_a_warning_is_never_read_from_the_alarmed_logs():
    # The drift reaches 2 only at the alarmed log 4 (median of 1.0, 2.2, 2.4): no warning.
    drifts = [1.0, 1.0, 2.2, 2.4, 2.6]
    w = first_warning("F", _with_drift(_rows("F", [0.4] * 5, alarm_from=4), drifts))
    assert (w.warning_log, w.alarm_log) == (None, 4)
    assert w.text == "no warning before the alarm at log 4 (day01-4)"
