"""The live benchmark (``python -m monitor.bench.live``) times what the daemon really does."""

from __future__ import annotations

from monitor.bench import live
from monitor.resources import resource_path


def test_a_log_with_an_alarm_gets_its_alarm_latency_and_state_change_cost() -> None:
    # 40 s of simulated boom cycles, spool wear from 24 s: the shipped model raises a fault
    # (at 30.6 s), so the daemon sends MON_Alarm on two state changes
    # (normal at the start, then fault).  The benchmark's wrappers must see those frames
    # and changes: once they sat on methods the frame pipeline no longer called.
    r = live.run(resource_path("config", "boom_default.model.npz"), 10, 40.0, 20.0)
    assert r["dropped"] == 0 and r["state_changes"] == ["normal", "fault"]
    # One MON_Alarm per state change (the fault's repeats are not state changes).
    assert len(r["alarm_frame_latency_ms"]) == 2
    assert all(v > 0 for v in r["alarm_frame_latency_ms"])
    # Each state change's cost to the detector thread was timed.
    assert len(r["state_change_detector_ms"]) == 2
    assert len(r["state_change_detector_cpu_ms"]) == 2


def test_four_loops_time_the_pump_rule_s_tick_once_per_row() -> None:
    # config/excavator4.yaml names a pump model: the daemon ticks the pump rule after the
    # four loops in every row, and the benchmark times that tick apart and with the row.
    r = live.run(resource_path("config", "boom_default.model.npz"), 10, 20.0, 20.0, loops=4)
    assert r["loops"] == 4
    assert r["pump_ticks"] == r["ticks"]  # one pump tick per row of four loop ticks
    assert 0 < r["pump_tick_cpu_median_us"] <= r["pump_tick_cpu_p99_us"]
    # the row's CPU with the pump is the four loops' and the pump's
    assert r["row_cpu_with_pump_median_ms"] > r["tick_cpu_median_ms"]
    assert r["row_with_pump_p50_ms"] >= r["tick_p50_ms"]
