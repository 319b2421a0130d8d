"""Time from the data: a CSV's ``t`` column decides the rows' times.  Rows at another rate are
resampled to 100 Hz (pressures and flows linear, commands held) or refused with the measured
rate; a time column that goes backwards, jumps absurdly or holds no time is refused with its
first bad line; a gap of more than 3 periods stays a gap.  Expected values are worked out by
hand from the rows written."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.cli import main
from monitor.errors import InputFileError
from monitor.io.csvio import read_csv
from monitor.io.timebase import MAX_SPAN_S, check_time
from monitor.signals import CSV_COLUMNS

HEADER = ",".join(CSV_COLUMNS)  # t, SpoolCmd, PumpDispCmd, EngineSpeed, OilTemp, PP, PA, PB, QP


def _row(t: float, spool: float = 10.0, pp: float = 100.0) -> str:
    return f"{t!r},{spool!r},100,2200,45,{pp!r},80,20,15.5"


def _csv(tmp_path, times, spool=None, pp=None, name: str = "rec.csv"):
    spool = [10.0] * len(times) if spool is None else spool
    pp = [100.0] * len(times) if pp is None else pp
    lines = [HEADER, *(_row(t, s, p) for t, s, p in zip(times, spool, pp, strict=True))]
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


# ------------------------------------------------------------------- rates


def test_rows_at_33_hz_are_refused_naming_the_rate(tmp_path) -> None:
    times = [round(i * 0.03, 6) for i in range(300)]
    with pytest.raises(InputFileError) as err:
        read_csv(_csv(tmp_path, times))
    msg = str(err.value)
    assert msg.startswith(f"{tmp_path / 'rec.csv'}: column 't': rows every 30 ms (33.3 Hz")
    assert "below 50 Hz" in msg and "\n" not in msg


def test_scaled_timestamps_are_refused(tmp_path) -> None:
    # t written in ms: rows 10 "s" apart, 0.1 Hz.
    times = [i * 10.0 for i in range(300)]
    with pytest.raises(InputFileError, match=r"rows every 10 s \(0\.1 Hz"):
        read_csv(_csv(tmp_path, times))


def test_rows_at_62_5_hz_are_resampled_linear_and_held(tmp_path) -> None:
    # Rows 16 ms apart.  PP rises 10 bar/s, so on the 10 ms grid linear interpolation gives
    # exactly 100 + 10 t; SpoolCmd is the row number, so a held value at grid instant k
    # (k * 10 ms) is the row at or before it: (10 k) // 16.
    n = 101  # 0 .. 1.6 s
    times = [round(i * 0.016, 6) for i in range(n)]
    rec = read_csv(
        _csv(
            tmp_path,
            times,
            spool=[float(i) for i in range(n)],
            pp=[100.0 + 10.0 * t for t in times],
        )
    )
    assert len(rec) == 161  # 0 .. 1.6 s every 10 ms
    np.testing.assert_allclose(rec.t, np.arange(161) * 0.01, atol=1e-12)
    np.testing.assert_allclose(rec["PP"], 100.0 + 10.0 * np.arange(161) * 0.01, atol=1e-9)
    assert rec["SpoolCmd"].tolist() == [float((10 * k) // 16) for k in range(161)]
    assert rec["PumpDispCmd"].tolist() == [100.0] * 161
    assert rec.meta["resampled_from_hz"] == pytest.approx(62.5)


def test_a_missing_sample_stays_missing_next_to_it(tmp_path) -> None:
    times = [round(i * 0.02, 6) for i in range(50)]  # 50 Hz
    path = _csv(tmp_path, times)
    lines = path.read_text().splitlines()
    lines[11] = lines[11].replace(",100.0,80,", ",,80,")  # PP of the row at 0.2 s (line 12)
    path.write_text("\n".join(lines) + "\n")
    rec = read_csv(path)
    pp = dict(zip(np.round(rec.t, 6).tolist(), rec["PP"].tolist(), strict=True))
    # 0.19 and 0.21 lie between the missing row and a good one; 0.18 and 0.22 are rows.
    assert np.isnan(pp[0.19]) and np.isnan(pp[0.2]) and np.isnan(pp[0.21])
    assert pp[0.18] == 100.0 and pp[0.22] == 100.0


def test_resampling_keeps_a_gap_a_gap(tmp_path) -> None:
    # 50 Hz: 0 .. 1.0 s, a 2 s gap (100 periods), then 3.0 .. 4.0 s.
    times = [round(i * 0.02, 6) for i in range(51)] + [round(3 + i * 0.02, 6) for i in range(51)]
    rec = read_csv(_csv(tmp_path, times))
    assert len(rec) == 2 * 101
    steps = np.diff(rec.t)
    assert np.count_nonzero(steps > 0.015) == 1
    assert rec.t[100] == pytest.approx(1.0) and rec.t[101] == pytest.approx(3.0)


def test_a_gap_at_100_hz_is_kept_as_read(tmp_path) -> None:
    times = [round(i * 0.01, 6) for i in range(100)] + [round(5 + i * 0.01, 6) for i in range(100)]
    rec = read_csv(_csv(tmp_path, times))
    assert rec.t.tolist() == times
    assert "resampled_from_hz" not in rec.meta


def test_jitter_of_a_few_ms_is_normal_100_hz(tmp_path) -> None:
    rng = np.random.default_rng(1)
    times = np.round(np.arange(500) * 0.01 + rng.uniform(-0.003, 0.003, 500), 6).tolist()
    rec = read_csv(_csv(tmp_path, times))
    assert rec.t.tolist() == times  # rows as read, not resampled


def test_the_resampling_is_said_in_one_line(tmp_path, capsys) -> None:
    times = [round(i * 0.02, 6) for i in range(100)]
    path = _csv(tmp_path, times)
    assert main(["encode", str(path), "--out", str(tmp_path / "out.log")]) == 0
    err = capsys.readouterr().err
    note = [line for line in err.splitlines() if "resampled" in line]
    assert note == [
        f"monitor encode: warning: {path}: 100 rows every 20 ms (50 Hz) "
        "resampled to 199 rows at 100 Hz (pressures and flows linear, commands "
        "held)"
    ]


# ------------------------------------------------------------- bad time columns


@pytest.mark.parametrize(
    ("times", "line", "words"),
    [
        ([0.0, 0.01, 1e300, 1e300 + 1], 4, "1e+300 s is not a time"),
        ([0.0, 0.01, 0.02, 0.015, 0.03], 5, "0.015 s is not after the previous 0.02 s"),
        ([0.0, 1000.0, 2000.0, 3000.0], 3, "jumps 1000 s after the previous row"),
        ([0.0, 0.01, 0.02, 0.03, 900.03, 900.04], 6, "jumps 900 s"),
        ([-2e10, 0.0, 0.01], 2, "-2e+10 s is not a time"),
    ],
    ids=["1e300", "backwards", "steps-of-1e3-s", "one-jump", "absurd-start"],
)
def test_bad_time_column_names_its_first_bad_line(tmp_path, times, line, words) -> None:
    path = _csv(tmp_path, times)
    with pytest.raises(InputFileError) as err:
        read_csv(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}:{line}: column 't'") and words in msg, msg


def test_a_recording_longer_than_a_year_is_refused() -> None:
    t = np.arange(0.0, MAX_SPAN_S + 1000.0, 500.0)  # steps allowed, the span not
    with pytest.raises(InputFileError, match="more than a year after the first row"):
        check_time(t, "x.csv", list(range(2, t.size + 2)))


def test_detect_refuses_33_hz_with_one_line_and_exit_2(tmp_path, capsys) -> None:
    times = [round(i * 0.03, 6) for i in range(3000)]
    path = _csv(tmp_path, times)
    assert main(["detect", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err
    assert err.startswith(f"monitor detect: error: {path}: column 't': rows every 30 ms")
