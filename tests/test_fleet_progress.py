"""What `monitor fleet run` prints while it works and at its end, and the output paths it
checks before any work starts (no cluster needed)."""

from __future__ import annotations

import io

import pyarrow as pa
import pyarrow.parquet as pq

from monitor.cli import main
from monitor.fleet.outcome import Outcome
from monitor.fleet.progress import Progress
from monitor.fleet.store import LOG_SCHEMA


class Clock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


def test_a_terminal_gets_one_line_redrawn_with_logs_machines_rate_and_time_left():
    out, clock = io.StringIO(), Clock()
    p = Progress(out, tty=True, clock=clock)
    p.commissioning(3)
    clock.t += 60
    p.commissioned()
    p.judging(10)
    for _ in range(4):  # 4 logs of 1,000 frames in 8 s: 0.5 logs/s, 6 logs left = 12 s
        clock.t += 2
        p.judged(1000)
    p.say("fleet: M04: a message")
    p.close()
    text = out.getvalue()
    assert "\n" not in text.split("fleet: M04")[0]  # the status was redrawn, not scrolled
    last_status = text.split("\r")[-2]
    assert "4/10 logs, 1/3 machines commissioned, 0.50 logs/s, 500 frames/s" in last_status
    assert "about 12 s left" in last_status
    # A message clears the status line, prints above it, and the status comes back.
    assert "\r\x1b[Kfleet: M04: a message\n\rfleet: 4/10 logs" in text
    assert text.endswith("68 s elapsed\n")


def test_a_log_file_gets_a_status_line_every_30_s_and_no_carriage_returns():
    out, clock = io.StringIO(), Clock()
    p = Progress(out, tty=False, every_s=30, clock=clock)
    p.judging(100)
    for _ in range(100):  # 100 logs, one a second
        clock.t += 1
        p.judged(10)
    p.close()
    lines = out.getvalue().splitlines()
    assert "\r" not in out.getvalue()
    # at 30, 60 and 90 s, then the closing status
    assert [ln.split(",")[0] for ln in lines] == [
        "fleet: 30/100 logs",
        "fleet: 60/100 logs",
        "fleet: 90/100 logs",
        "fleet: 100/100 logs",
    ]


def _row(log: str, verdict: str, error: str | None) -> dict:
    return {"log": log, "sha256": "ab", "verdict": verdict, "error": error}


def test_the_closing_line_counts_judged_not_judged_and_failed_and_names_the_first_failures():
    rows = [
        _row("M01/logs/a.log", "healthy", None),
        _row("M01/logs/b.log", "fault", None),
        _row("M02/logs/a.log", "not_judged", None),
        _row("M02/logs/b.log", "not_judged", "InputFileError: line 1: not a candump line"),
        _row("M03/logs/a.csv", "not_judged", "InputFileError: no column QP"),
        _row("M03/logs/b.log", "not_judged", "unreadable: Permission denied"),
        _row("M04/logs/gone.log", "not_judged", "an old row of a log since removed"),
    ]
    keys = {(r["log"], "", "ab") for r in rows[:-1]}
    o = Outcome.of(rows, keys, new=4, skipped=2)
    assert (o.judged, o.not_judged, o.failed, o.exit_code) == (2, 1, 3, 3)
    assert o.line() == (
        "fleet: 6 logs: 2 judged, 1 not judged, 3 failed (M02/logs/b.log: InputFileError: line "
        "1: not a candump line; M03/logs/a.csv: InputFileError: no column QP; 1 more); 4 new "
        "this run, 2 already in results"
    )
    healthy = Outcome.of(rows[:3], keys, new=3, skipped=0)
    assert healthy.exit_code == 0 and "0 failed;" in healthy.line()


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def test_an_existing_file_as_out_is_one_line_and_exit_2_before_any_work(tmp_path, capsys):
    file = tmp_path / "taken"
    file.write_text("x")
    fleet = tmp_path / "fleet"
    (fleet / "M01" / "logs").mkdir(parents=True)
    assert main(["fleet", "run", str(fleet), "--out", str(file)]) == 2
    assert f"cannot write into {file}: {file} is not a folder" in _one_line(capsys)
    assert main(["fleet", "report", str(tmp_path), "--out", str(file)]) == 2
    assert f"cannot write into {file}: {file} is not a folder" in _one_line(capsys)
    assert main(["simulate-fleet", str(file), "--machines", "1", "--days", "1"]) == 2
    assert f"cannot write into {file}: {file} is not a folder" in _one_line(capsys)
    assert file.read_text() == "x"


def test_a_machine_folder_given_as_the_fleet_is_one_line_and_exit_2(tmp_path, capsys):
    machine = tmp_path / "M01"
    (machine / "logs").mkdir(parents=True)
    (machine / "logs" / "day01.log").write_text("(0.0) can0 123#00\n")
    assert main(["fleet", "run", str(machine), "--out", str(tmp_path / "r")]) == 2
    assert "one machine's folder" in _one_line(capsys)
    assert not (tmp_path / "r").exists()


def test_report_on_empty_results_says_so_in_one_line(tmp_path, capsys):
    # What an interrupted first run left before: a logs.parquet of no rows.
    pq.write_table(pa.Table.from_pylist([], LOG_SCHEMA), tmp_path / "logs.parquet")
    assert main(["fleet", "report", str(tmp_path), "--out", str(tmp_path / "page")]) == 2
    assert "no rows yet" in _one_line(capsys)
