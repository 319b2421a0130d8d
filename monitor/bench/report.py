"""The machine a run was measured on, and the markdown table of a ``monitor bench`` result."""

from __future__ import annotations

import os
import platform
from typing import Any

import numba
import numpy as np


def machine() -> dict[str, Any]:
    model = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as fh:
            for line in fh:
                if line.startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return {
        "cpu": model,
        "cores": os.cpu_count(),
        "numba_threads": numba.get_num_threads(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "numba": numba.__version__,
        "system": f"{platform.system()} {platform.release()}",
    }


def load_average() -> list[float] | None:
    try:
        return [round(v, 2) for v in os.getloadavg()]
    except OSError:
        return None


def _f(v: float | None, digits: int = 1) -> str:
    return "-" if v is None else f"{v:,.{digits}f}"


def markdown(result: dict[str, Any]) -> str:
    m = result["machine"]
    lines = [
        f"Machine: {m['cpu']}, {m['cores']} cores ({m['numba_threads']} numba threads), "
        f"Python {m['python']}, numba {m['numba']}; load average {result['load_before']} "
        f"before, {result['load_after']} after"
        + (" (quick run: reduced sizes)" if result["quick"] else "")
        + ".",
        "",
        *_headline_table(result),
        "",
        *_grnn_table(result["grnn"]),
        "",
        _live(result["live"]),
        "",
        _four_loops(result["four_loop"]),
        "",
        _detect(result["detect"]),
    ]
    return "\n".join(lines) + "\n"


def _headline_table(result: dict[str, Any]) -> list[str]:
    """Each headline figure with its unit, its goal and whether it was met."""
    goals = result["goals"]
    lines = [
        "| measurement | value | goal | met |",
        "|---|---|---|---|",
    ]
    for key, unit, digits in (
        ("grnn_us_per_query", "us", 2),
        ("grnn_speedup_vs_numba_loop", "x", 0),
        ("grnn_max_rel_error", "of std", 9),
        ("tick_p99_ms", "ms", 3),
        ("four_loop_tick_p99_ms", "ms", 3),
        ("detect_realtime_factor", "x real time", 0),
        ("detect_speedup_vs_reference_pipeline", "x", 0),
        ("cli_help_s", "s", 2),
        ("cli_help_rss_mb", "MB", 0),
        ("daemon_start_s", "s", 2),
        ("first_run_s", "s", 1),
        ("daemon_rss_mb", "MB", 0),
        ("daemon_peak_rss_mb", "MB", 0),
        ("daemon_rss_growth_mb", "MB", 1),
        ("daemon_start_jit_s", "s", 2),
        ("daemon_rss_mb_jit", "MB", 0),
        ("daemon_peak_rss_mb_jit", "MB", 0),
        ("warm_up_s", "s", 1),
        ("detect_rss_mb", "MB", 0),
        ("detect_s", "s", 2),
        ("detect_rss_mb_jit", "MB", 0),
        ("detect_s_jit", "s", 2),
    ):
        goal = goals.get(key)
        met = "" if goal is None else ("yes" if goal["met"] else "**no**")
        value = result[key]
        shown = f"{value:.2e}" if key == "grnn_max_rel_error" else _f(value, digits)
        lines.append(f"| `{key}` | {shown} {unit} | {goal['text'] if goal else ''} | {met} |")
    return lines


def _grnn_table(g: dict[str, Any]) -> list[str]:
    """Query and tick times by patterns and horizon: ours, the plain loop and pyGRNN."""
    lines = [
        f"GRNN (paper preset, {g['models'][next(iter(g['models']))]['inputs']} inputs), "
        "median time; pyGRNN per tick = p x its per-query time:",
        "",
        "| patterns | p | cut-off us/query | plain loop us/query | pyGRNN us/query | "
        "cut-off us/tick | plain us/tick | pyGRNN us/tick | speedup vs plain (tick) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for c in g["cells"]:
        lines.append(
            f"| {c['patterns']:,} | {c['p']} | {_f(c['cutoff_us_per_query'], 2)} | "
            f"{_f(c['plain_us_per_query'])} | {_f(c['pygrnn_us_per_query'], 0)} | "
            f"{_f(c['cutoff_us_per_tick'])} | {_f(c['plain_us_per_tick'])} | "
            f"{_f(c['pygrnn_us_per_tick_derived'], 0)} | "
            f"{c['plain_us_per_tick'] / c['cutoff_us_per_tick']:.0f}x |"
        )
    return lines


def _live(live: dict[str, Any]) -> str:
    alarm_ms = live["alarm_frame_latency_ms"]
    return (
        f"Live daemon ({live['model_summary']['patterns']:,} patterns, p = {live['horizon']}, "
        f"{live['seconds_of_data']:.0f} s of 100 Hz data at {live['speed']:g}x on a virtual "
        f"bus, {live['ticks']:,} ticks): latency p50 {live['tick_p50_ms']:.3f} ms, p99 "
        f"{live['tick_p99_ms']:.3f} ms, max {live['tick_max_ms']:.1f} ms (p99 "
        f"{live['tick_p99_ms_away_from_state_changes']:.3f} ms without the "
        f"{live['ticks_near_state_changes']} ticks within 2 s after a state change); "
        f"CPU per tick median "
        f"{live['tick_cpu_median_ms']:.3f} ms, p99 {live['tick_cpu_p99_ms']:.3f} ms; "
        f"state change to MON_Alarm sent: "
        + (", ".join(f"{v:.2f} ms" for v in alarm_ms) if alarm_ms else "none")
        + f"; peak RSS {live['peak_rss_mb']:.0f} MB ({live['rss_after_load_mb']:.0f} MB after "
        f"loading); {live['dropped']} frames dropped."
    )


def _detect(det: dict[str, Any]) -> str:
    return (
        f"`monitor detect` ({det['model_summary']['patterns']:,} patterns, p = 1) on a "
        f"{det['log_s']:.0f} s log of {det['log_frames']:,} frames: {det['detect_s']:.2f} s "
        f"in-process ({det['detect_frames_per_s']:,.0f} frames/s, "
        f"{det['detect_realtime_factor']:,.0f}x real time; parts "
        + ", ".join(f"{k} {v:.2f}" for k, v in det["detect_parts_s"].items())
        + f"; the detect part takes {det['detect_s_without_isolation']:.2f} s without fault "
        f"isolation, which runs per sample during the last {det['fault_s_in_log']:.0f} s in "
        f"fault), CLI cold {det['detect_cli_cold_wall_s']:.1f} s wall.  Reference (python-can "
        f"LogReader + cantools + pyGRNN) on the first {det['reference_slice_s']:.0f} s: "
        f"{det['reference_us_per_frame']:.0f} us/frame vs {det['ours_us_per_frame']:.2f} "
        f"us/frame: {det['detect_speedup_vs_reference_pipeline']:,.0f}x (their predictions "
        f"agree to {det['reference_max_abs_diff_z']:.1e} z)."
    )


def _four_loops(four: dict[str, Any]) -> str:
    return (
        f"Four loops in one daemon (config/excavator4.yaml, each loop on the model above and "
        f"the same run, {four['seconds_of_data']:.0f} s at {four['speed']:g}x, "
        f"{four['frames']:,} frames, {four['ticks']:,} rows of four ticks): row latency "
        f"(frame completing the row to the last loop's result) p50 "
        f"{four['tick_p50_ms']:.3f} ms, p99 {four['tick_p99_ms']:.3f} ms, max "
        f"{four['tick_max_ms']:.1f} ms; CPU per row (four ticks) median "
        f"{four['tick_cpu_median_ms']:.3f} ms, p99 {four['tick_cpu_p99_ms']:.3f} ms, of a "
        f"10 ms sample period; peak RSS {four['peak_rss_mb']:.0f} MB; {four['dropped']} "
        "frames dropped." + _pump(four)
    )


def _pump(four: dict[str, Any]) -> str:
    """The pump rule's tick beside the four loops' (config/excavator4.yaml's `pump:`)."""
    if "pump_tick_cpu_median_us" not in four:
        return ""
    return (
        f" The pump rule after them (its tick, MON_Alarm_Pump and DM1): CPU median "
        f"{four['pump_tick_cpu_median_us']:.1f} us, p99 {four['pump_tick_cpu_p99_us']:.1f} us "
        f"per row ({four['pump_share_of_row_cpu_median']:.1%} of the row's CPU); the row "
        f"with it: latency p50 {four['row_with_pump_p50_ms']:.3f} ms, p99 "
        f"{four['row_with_pump_p99_ms']:.3f} ms, CPU median "
        f"{four['row_cpu_with_pump_median_ms']:.3f} ms, p99 "
        f"{four['row_cpu_with_pump_p99_ms']:.3f} ms."
    )
