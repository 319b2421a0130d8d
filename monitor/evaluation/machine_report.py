"""Aggregates of ``monitor eval-sim --machine excavator4`` and their markdown tables.

Per loop: false alarms per hour of normal operation (entries into the fault state, with the
one-sided 95 % Poisson bound, as the boom's evaluation) and sensor findings.  Per fault and
severity: detected (the faulty loop's alarm at or after the onset; the pump's: the pump
rule's, or any loop's without one), the median delay, the loop named (the machine's finding,
``monitor.detection.machine``: the pump when its rule alarmed, else the first loop to alarm
after the onset; right = the faulty loop), the runs that named the pump, and the runs in
which a neighbour's alarm was raised too, by loop (raised, whatever the finding named).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from monitor.detection.pump import PUMP
from monitor.evaluation.machine_eval import MachineUnderTest
from monitor.evaluation.machine_plan import (
    DEV_SEEDS,
    MACHINE_SEED_BASE,
    MachinePlan,
    fault_runs,
    normal_runs,
)
from monitor.evaluation.report import (
    TABLE1_MIN_SEVERITY,
    _fa,
    _false_alarms,
    _pct,
    _sec,
    detection_cell,
)


def fault_cell(runs: Sequence[dict[str, Any]], loops: Sequence[str]) -> dict[str, Any]:
    """Detection, delay, the loop named and neighbours' alarms over ``runs``."""
    detected = [r for r in runs if r["detected"]]
    right = sum(r["right_loop"] for r in detected)
    return {
        **detection_cell(runs),
        "named_right": right,
        "right_loop_rate": right / len(detected) if detected else None,
        "named": {n: sum(r["named"] == n for r in runs) for n in (*loops, PUMP, "none")},
        "pump_named": sum(r["named"] == PUMP for r in runs),
        "explained_by_pump_runs": sum(bool(r.get("explained_by_pump")) for r in runs),
        "neighbour_alarm_runs": sum(bool(r["neighbours"]) for r in runs),
        "neighbour_alarms": {n: sum(n in r["neighbours"] for r in runs) for n in loops},
        "pre_onset_false_alarms": sum(sum(r["pre_onset_alarms"].values()) for r in runs),
    }


def loop_rows(m: MachineUnderTest, plan: MachinePlan) -> dict[str, Any]:
    """Per loop: its model, false alarms on normal runs and before the faults' onsets."""
    pre_hours = len(m.faults) * plan.onset_s / 3600.0
    out = {}
    for name, model in m.models.items():
        normal = m.normal[name]
        hours = sum(r["duration_s"] for r in normal) / 3600.0
        levels = [r["max_level"] for r in normal if r["max_level"] is not None]
        pre = [{"pre_onset_alarms": r["pre_onset_alarms"][name]} for r in m.faults]
        out[name] = {
            "model": str(next(lc.model for lc in m.config.monitored_loops if lc.name == name)),
            "preset": model.training.get("preset"),
            "outputs": list(model.spec.outputs),
            "false_alarms_normal": _false_alarms(normal, hours, "alarm_episodes"),
            "normal_max_level": max(levels) if levels else None,
            "normal_runs_with_sensor_fault": sum(bool(r["sensor_fault"]) for r in normal),
            "false_alarms_pre_onset": _false_alarms(pre, pre_hours, "pre_onset_alarms"),
        }
    if m.pump is not None:
        out[PUMP] = _pump_row(m, plan, pre_hours)
    return out


def _pump_row(m: MachineUnderTest, plan: MachinePlan, pre_hours: float) -> dict[str, Any]:
    """The pump rule's false alarms, as a loop's."""
    assert m.pump is not None
    model = m.pump[0]
    normal = m.normal[PUMP]
    hours = sum(r["duration_s"] for r in normal) / 3600.0
    levels = [r["max_level"] for r in normal if r["max_level"] is not None]
    pre = [{"pre_onset_alarms": r["pre_onset_alarms"][PUMP]} for r in m.faults]
    return {
        "model": str(m.config.pump.model) if m.config.pump else None,
        "preset": "pump margin law",
        "outputs": ["margin residual (bar)"],
        "threshold_bar": model.threshold_bar,
        "off_reason": model.off_reason,
        "false_alarms_normal": _false_alarms(normal, hours, "alarm_episodes"),
        "normal_max_level": max(levels) if levels else None,
        "normal_runs_with_sensor_fault": 0,
        "normal_runs_not_judged": sum(r["verdict"] == "not_judged" for r in normal),
        "false_alarms_pre_onset": _false_alarms(pre, pre_hours, "pre_onset_alarms"),
    }


def fault_rows(m: MachineUnderTest, plan: MachinePlan) -> list[dict[str, Any]]:
    """One cell per fault and severity (onsets pooled, then each onset kind)."""
    out = []
    for fault in plan.faults:
        for sev in plan.severities:
            runs = [r for r in m.faults if r["fault"] == fault and r["severity"] == sev]
            row = {"fault": fault, "loop": fault.partition(".")[0], "severity": sev}
            row["all"] = fault_cell(runs, m.loops)
            for onset in plan.onsets:
                row[onset] = fault_cell([r for r in runs if r["onset"] == onset], m.loops)
            out.append(row)
    return out


def by_faulty_loop(m: MachineUnderTest) -> dict[str, dict[str, Any]]:
    """The issue's measures per faulty loop: severity >= 0.5 pooled, and 0.3 alone."""
    out = {}
    for loop in dict.fromkeys(r["loop"] for r in m.faults):
        mine = [r for r in m.faults if r["loop"] == loop]
        out[loop] = {
            f"severity>={TABLE1_MIN_SEVERITY}": fault_cell(
                [r for r in mine if r["severity"] >= TABLE1_MIN_SEVERITY - 1e-9], m.loops
            ),
            "severity=0.3": fault_cell(
                [r for r in mine if abs(r["severity"] - 0.3) < 1e-9], m.loops
            ),
        }
    return out


def machine_record(
    rerun: str,
    config_path: str,
    plan: MachinePlan,
    m: MachineUnderTest,
    workers: int,
    timing: dict[str, float],
) -> dict[str, Any]:
    """The JSON ``monitor eval-sim --machine excavator4`` writes."""
    return {
        "rerun": rerun,
        "machine": "excavator4",
        "monitor_config": config_path,
        "config": plan.to_dict(),
        "plan": {
            "fault_runs": len(fault_runs(plan)),
            "normal_runs": len(normal_runs(plan)),
            "normal_hours": plan.normal_hours,
            "cycle": "mixed",
            "test_seeds": f"normal: {MACHINE_SEED_BASE}+i; fault: {MACHINE_SEED_BASE} + 100000 "
            "+ 200000*onset + 15000*fault + 100*round(100*severity) + run; plus 10000000 x "
            "seed set",
            "seed_set": plan.seed_set,
            "development_seeds": DEV_SEEDS,
            "workers": workers,
        },
        "loops": loop_rows(m, plan),
        "by_faulty_loop": by_faulty_loop(m),
        "faults": fault_rows(m, plan),
        "runs": {"normal": m.normal, "fault": m.faults},
        "runtime_s": {
            "total": round(timing["total"], 1),
            "simulate": round(timing["simulate_s"], 1),
            "detect": round(m.detect_s, 1),
        },
    }


def _named(c: dict[str, Any]) -> str:
    if not c["detected"]:
        return "-"
    return f"{c['named_right']}/{c['detected']} ({_pct(c['right_loop_rate'])})"


def _neighbours(c: dict[str, Any]) -> str:
    hit = [f"{n} {k}" for n, k in c["neighbour_alarms"].items() if k]
    return f"{c['neighbour_alarm_runs']}" + (f" ({', '.join(hit)})" if hit else "")


def _loop_table(loops: dict[str, Any]) -> list[str]:
    lines = [
        "| loop | model outputs | false alarms on normal runs | largest level | sensor finding "
        "| false alarms before an onset |",
        "|---|---|---|---:|---:|---|",
    ]
    for name, r in loops.items():
        level = "-" if r["normal_max_level"] is None else f"{r['normal_max_level']:.2f}"
        lines.append(
            f"| {name} | {', '.join(r['outputs'])} | {_fa(r['false_alarms_normal'])} | {level} "
            f"| {r['normal_runs_with_sensor_fault']} runs | {_fa(r['false_alarms_pre_onset'])} |"
        )
    return lines


def machine_markdown(result: dict[str, Any]) -> str:
    """The report: loops' false alarms, the issue's measures per faulty loop, every cell."""
    cfg, plan, rt = result["config"], result["plan"], result["runtime_s"]
    lines = [
        "## Simulated evaluation of the whole machine (`monitor eval-sim --machine excavator4`)",
        "",
        f"{plan['normal_runs']} normal runs ({plan['normal_hours']:g} h of {plan['cycle']} duty "
        f"cycles per loop) and {plan['fault_runs']} fault runs ({len(cfg['faults'])} faults x "
        f"{len(cfg['severities'])} severities x {len(cfg['onsets'])} onsets x {cfg['runs']} runs;"
        f" onset at {cfg['onset_s']:g} s, {cfg['duration_s']:g} s long), seed set "
        f"{plan['seed_set']} (the shipped models were developed on seeds "
        f"{plan['development_seeds']}), judged by the loops of {result['monitor_config']}. "
        f"Run time {rt['total']:.0f} s (simulation {rt['simulate']:.0f} s, detection "
        f"{rt['detect']:.0f} s).",
        "",
        *_loop_table(result["loops"]),
    ]
    lines += [
        "",
        "Per faulty loop (detected: the loop's own alarm; the pump's: the pump rule's, or "
        "any loop's without one; named: the machine's finding, the pump when its rule "
        "alarmed, else the first loop to alarm after the onset, is the faulty one, of the "
        "detected runs; pump named: runs whose finding was the pump; neighbour: runs in "
        "which another loop alarmed after the onset, whatever the finding named):",
        "",
        "| faulty loop | severities | runs | detected | median delay | named right "
        "| pump named | runs with a neighbour's alarm |",
        "|---|---|---:|---:|---:|---|---:|---|",
    ]
    for loop, cells in result["by_faulty_loop"].items():
        for sev, c in cells.items():
            if c["runs"]:
                lines.append(
                    f"| {loop} | {sev.partition('severity')[2]} | {c['runs']} | "
                    f"{_pct(c['detection_rate'])} | {_sec(c['median_delay_s'])} | {_named(c)} "
                    f"| {c['pump_named']} | {_neighbours(c)} |"
                )
    lines += [
        "",
        "Per fault and severity (onsets pooled):",
        "",
        "| fault | severity | runs | detected | median delay | named right | named "
        "| runs with a neighbour's alarm |",
        "|---|---:|---:|---:|---:|---|---|---|",
    ]
    for row in result["faults"]:
        c = row["all"]
        first = ", ".join(f"{n} {k}" for n, k in c["named"].items() if k)
        lines.append(
            f"| {row['fault']} | {row['severity']:g} | {c['runs']} | "
            f"{_pct(c['detection_rate'])} | {_sec(c['median_delay_s'])} | {_named(c)} | "
            f"{first} | {_neighbours(c)} |"
        )
    return "\n".join(lines)
