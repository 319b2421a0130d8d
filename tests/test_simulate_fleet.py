"""`monitor simulate-fleet`: the layout, the wear schedule and the answer key it promises."""

from __future__ import annotations

import json

import pytest

from monitor.cli import main


def test_several_logs_a_day_are_named_in_time_order_and_wear_rises_log_by_log(tmp_path):
    out = tmp_path / "F"
    args = [
        "simulate-fleet",
        str(out),
        "--machines",
        "1",
        "--days",
        "2",
        "--logs-per-day",
        "2",
        "--log-s",
        "60",
        "--commissioning-s",
        "180",
        "--wear-max",
        "0.6",
    ]
    assert main(args) == 0
    logs = sorted(p.name for p in (out / "M01" / "logs").iterdir())
    assert logs == ["day01-1.log", "day01-2.log", "day02-1.log", "day02-2.log"]
    key = json.loads((out / "answer_key.json").read_text())
    days = key["machines"]["M01"]["days"]
    assert [d["log"] for d in days] == [f"M01/logs/{n}" for n in logs]
    # Linear from 0 in the first log to --wear-max in the last: 0.6 x j / 3.
    assert [d["severity"] for d in days] == pytest.approx([0.0, 0.2, 0.4, 0.6])
    assert [d["day"] for d in days] == [1, 1, 2, 2]
    oil = key["oil_temp_c_per_day"]
    assert [d["oil_temp_c"] for d in days] == [oil[0], oil[0], oil[1], oil[1]]


def test_too_many_logs_a_day_is_one_line_and_exit_2(tmp_path, capsys):
    args = [
        "simulate-fleet",
        str(tmp_path / "F"),
        "--machines",
        "1",
        "--days",
        "2",
        "--logs-per-day",
        "30",
    ]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["monitor simulate-fleet: error: --logs-per-day must be 1..24, got 30"]
    assert not (tmp_path / "F").exists()
