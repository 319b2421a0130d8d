"""``monitor bench --quick``: the benchmark pipeline runs and reports sane numbers (not speed)."""

from __future__ import annotations

import json
import math
import shutil

import pytest

from monitor.cli import main

KEYS = (
    "grnn_us_per_query",
    "grnn_speedup_vs_numba_loop",
    "grnn_max_rel_error",
    "tick_p99_ms",
    "four_loop_tick_p99_ms",
    "detect_realtime_factor",
    "detect_speedup_vs_reference_pipeline",
    "cli_help_s",
    "cli_help_rss_mb",
    "daemon_start_s",
    "first_run_s",
    "daemon_rss_mb",
    "daemon_peak_rss_mb",
    "detect_rss_mb",
    "detect_rss_mb_jit",
)


@pytest.fixture(scope="module")
def quick(tmp_path_factory, warm_numba_cache):
    pytest.importorskip("pyGRNN")
    out = tmp_path_factory.mktemp("bench")
    # The shortest RSS sampling: the test checks the numbers are measured, not their size.
    # The warm figures with the cache test_startup checks (`monitor warm-up` twice, there):
    # one cold compile of every kernel for both files.
    code = main(
        [
            "bench",
            "--quick",
            "--footprint-s",
            "5",
            "--json",
            str(out / "b.json"),
            "--work-dir",
            str(out),
            "--numba-cache",
            str(warm_numba_cache[1]),
        ]
    )
    assert code == 0
    return out, json.loads((out / "b.json").read_text())


def test_contract_keys_are_measured_numbers(quick):
    _, r = quick
    for key in KEYS:
        assert isinstance(r[key], float) and math.isfinite(r[key]) and r[key] >= 0, key
    assert r["quick"] is True
    assert set(r["goals"]) <= set(r)


def test_values_are_consistent_with_their_parts(quick):
    out, r = quick
    g, live, det = r["grnn"], r["live"], r["detect"]
    assert r["grnn_max_rel_error"] <= 1e-6  # the stated bound, measured on real queries
    assert r["grnn_speedup_vs_numba_loop"] == pytest.approx(
        next(
            c["plain_us_per_query"] / c["cutoff_us_per_query"]
            for c in g["cells"]
            if c["patterns"] == g["grnn_headline_patterns"] and c["p"] == 1
        )
    )
    assert {(c["patterns"] > 0, c["p"]) for c in g["cells"]} == {(True, 1), (True, 10)}
    # Every frame put on the bus was processed, one tick per 10 ms row.
    assert live["dropped"] == 0
    assert live["ticks"] == pytest.approx(live["seconds_of_data"] * 100, abs=2)
    assert live["tick_p50_ms"] <= live["tick_p99_ms"] <= live["tick_max_ms"]
    assert live["peak_rss_mb"] > 0
    # Four loops: every row ticked by each of the four, nothing dropped, CPU of four ticks.
    four = r["four_loop"]
    assert four["loops"] == 4 and four["dropped"] == 0
    assert four["ticks"] == pytest.approx(four["seconds_of_data"] * 100, abs=2)
    assert r["four_loop_tick_p99_ms"] == four["tick_p99_ms"] >= four["tick_p50_ms"]
    assert four["frames"] > 3.9 * live["frames"] * four["seconds_of_data"] / live["seconds_of_data"]
    assert det["detect_realtime_factor"] == pytest.approx(det["log_s"] / det["detect_s"])
    assert det["alarm"] is True  # the log's fault is found: alarms are part of the timing
    assert det["reference_max_abs_diff_z"] < 1e-6  # the reference did the same work
    # The daemon alone: its steady RSS (a median of samples) never above its peak.
    assert 0 < r["daemon_rss_mb"] <= r["daemon_peak_rss_mb"]
    # `monitor detect` after warm-up loads no numba where g++ built the module; the JIT does.
    assert r["detect_numba_loaded_jit"] == 1.0
    if shutil.which("g++"):
        assert r["detect_numba_loaded"] == 0.0
    assert (out / "b.md").read_text().count("|") > 20
    assert (out / "b.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_unwritable_output_is_a_clear_error(tmp_path, capsys):
    code = main(["bench", "--quick", "--json", str(tmp_path / "no" / "b.json")])
    assert code == 2
    assert "does not exist" in capsys.readouterr().err


def test_a_numba_cache_that_no_warm_up_filled_is_refused_before_the_work(tmp_path, capsys):
    # Measured with an empty cache, the "warm" start would be a cold one under a warm name.
    assert main(["bench", "--quick", "--numba-cache", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "argument --numba-cache" in err
    assert f"{tmp_path} holds no numba cache" in err and "monitor warm-up" in err
    assert main(["bench", "--quick", "--numba-cache", str(tmp_path / "none")]) == 2
    assert "is not a folder" in capsys.readouterr().err
