"""Aggregates of the simulated evaluation, and its markdown tables.

Rates are fractions of runs (0..1); delays are seconds from the fault onset; isolation
accuracy is the share of *detected* runs whose alarm named the true fault (a missed run has
nothing to isolate; the confusion matrix shows misses as ``none``).
"""

from __future__ import annotations

import statistics
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from monitor.evaluation.exercised import exercised_cell, exercised_markdown
from monitor.evaluation.rates import poisson_rate_upper
from monitor.evaluation.sim_eval import EvalConfig, ModelUnderTest, fault_plan, normal_plan
from monitor.signals import FAULT_NAMES

#: Confusion-matrix columns: what an alarm named, or ``none`` for a missed run.
ISOLATION_LABELS = (*FAULT_NAMES, "unknown", "none")
#: The paper's Table 1 pools the severities a maintenance crew cares about.
TABLE1_MIN_SEVERITY = 0.5


def detection_cell(runs: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Runs, detected, the rate and the median and largest delay (s) over fault ``runs``
    (rows with ``detected`` and ``delay_s``): the first keys of every evaluation's cell."""
    detected = [r for r in runs if r["detected"]]
    delays = [r["delay_s"] for r in detected]
    return {
        "runs": len(runs),
        "detected": len(detected),
        "detection_rate": len(detected) / len(runs) if runs else None,
        "median_delay_s": statistics.median(delays) if delays else None,
        "max_delay_s": max(delays) if delays else None,
    }


def _cell(runs: Sequence[dict[str, Any]]) -> dict[str, Any]:
    detected = [r for r in runs if r["detected"]]
    correct = sum(r["isolated"] == r["fault"] for r in detected)
    return {
        **detection_cell(runs),
        "isolation_accuracy": correct / len(detected) if detected else None,
        "pre_onset_false_alarms": sum(r["pre_onset_alarms"] for r in runs),
        **exercised_cell(runs),
    }


def _confusion(runs: Iterable[dict[str, Any]], faults: Sequence[str]) -> dict[str, Any]:
    m = {f: dict.fromkeys(ISOLATION_LABELS, 0) for f in faults}
    for r in runs:
        m[r["fault"]][r["isolated"] if r["isolated"] in ISOLATION_LABELS else "unknown"] += 1
    return m


def _false_alarms(runs: Sequence[dict[str, Any]], hours: float, key: str) -> dict[str, Any]:
    episodes = sum(r[key] for r in runs)
    return {
        "runs": len(runs),
        "hours": round(hours, 4),
        "alarm_episodes": episodes,
        "runs_with_alarm": sum(r[key] > 0 for r in runs),
        "per_hour": episodes / hours if hours > 0 else None,
        # One-sided 95 % Poisson bound (about 3/hours with no episode seen: rule of three).
        "per_hour_95_upper": poisson_rate_upper(episodes, hours) if hours > 0 else None,
    }


def aggregate(m: ModelUnderTest, cfg: EvalConfig) -> dict[str, Any]:
    """Everything the JSON reports for one model."""
    faults = [f for f in FAULT_NAMES if f in cfg.faults]
    per_sev: list[dict[str, Any]] = []
    for fault in faults:
        for sev in cfg.severities:
            row: dict[str, Any] = {"fault": fault, "severity": sev}
            for onset in (*cfg.onsets, "all"):
                runs = [
                    r
                    for r in m.faults
                    if r["fault"] == fault
                    and r["severity"] == sev
                    and (onset == "all" or r["onset"] == onset)
                ]
                row[onset] = _cell(runs)
            per_sev.append(row)
    high = [r for r in m.faults if r["severity"] >= TABLE1_MIN_SEVERITY - 1e-9]
    table1 = {f: _cell([r for r in high if r["fault"] == f]) for f in faults}
    table1["all_faults"] = _cell(high)
    normal_hours = sum(r["duration_s"] for r in m.normal) / 3600.0
    pre_hours = len(m.faults) * cfg.onset_s / 3600.0
    normal_margin = [r["max_J_over_eps0"] for r in m.normal if r["max_J_over_eps0"] is not None]
    g = m.model.dgrnn.grnn
    return {
        "source": m.source,
        "preset": m.model.training.get("preset"),
        "outputs": list(m.model.spec.outputs),
        "patterns": int(g.patterns_.shape[0]),
        "sigma": float(g.sigma_),
        "window_N": m.model.window_n,
        "horizon": cfg.horizon or m.model.spec.horizon,
        "threshold_rule": m.model.threshold.rule,
        "J0": m.model.j0,
        "eps0": m.model.eps0,
        "false_alarms_normal": _false_alarms(m.normal, normal_hours, "alarm_episodes"),
        "normal_max_J_over_eps0": max(normal_margin) if normal_margin else None,
        "false_alarms_pre_onset": _false_alarms(m.faults, pre_hours, "pre_onset_alarms"),
        "table1": table1,
        "per_severity": per_sev,
        "confusion": {
            "columns": list(ISOLATION_LABELS),
            "all": _confusion(m.faults, faults),
            f"severity>={TABLE1_MIN_SEVERITY}": _confusion(high, faults),
        },
        "runtime_s": {"train": round(m.train_s, 1), "detect": round(m.detect_s, 1)},
        "detect_s_per_run_minute": round(
            m.detect_s / max(1e-9, sum(r["duration_s"] for r in m.normal + m.faults) / 60), 3
        ),
        "runs": {"normal": m.normal, "fault": m.faults},
    }


# ------------------------------------------------------------------------------- markdown


@dataclass(frozen=True)
class Training:
    """The presets' training runs: their seeds, each one's length, and the simulated faulty
    runs per fault and severity behind their fault signatures."""

    seeds: tuple[int, ...]
    duration_s: float
    isolation_runs: int


def evaluation_record(
    rerun: str,
    cfg: EvalConfig,
    models: Sequence[ModelUnderTest],
    training: Training | None,
    workers: int,
    timing: dict[str, float],
) -> dict[str, Any]:
    """The JSON ``monitor eval-sim`` writes: the command that reruns it, the plan, every
    model's scores and the time spent (``timing``: ``simulate_s`` and ``total``)."""
    return {
        "rerun": rerun,
        "config": cfg.to_dict(),
        "plan": {
            "fault_runs": len(fault_plan(cfg)),
            "normal_runs": len(normal_plan(cfg)),
            "normal_hours": cfg.normal_hours,
            "train_seeds": None if training is None else list(training.seeds),
            "train_duration_s": None if training is None else training.duration_s,
            "train_isolation_runs": None if training is None else training.isolation_runs,
            "test_seeds": "normal: 100000+i; fault: 1000000 + 100000*fault + 50000*onset "
            "+ 100*round(100*severity) + run; plus 10000000 x seed set",
            "seed_set": cfg.seed_set,
            "workers": workers,
        },
        "models": {m.label: aggregate(m, cfg) for m in models},
        "runtime_s": {
            "total": round(timing["total"], 1),
            "simulate": round(timing["simulate_s"], 1),
            "train": {m.label: round(m.train_s, 1) for m in models},
            "detect": {m.label: round(m.detect_s, 1) for m in models},
        },
    }


def _pct(v: float | None) -> str:
    return "-" if v is None else f"{100 * v:.0f} %"


def _sec(v: float | None) -> str:
    return "-" if v is None else f"{v:.1f} s"


def _fa(d: dict[str, Any]) -> str:
    if d["per_hour"] is None:
        return "- (no normal data)"
    text = f"{d['alarm_episodes']} in {d['hours']:.2f} h = {d['per_hour']:.2f}/h"
    if d["per_hour_95_upper"] is not None:
        text += f" (< {d['per_hour_95_upper']:.2f}/h at 95 %)"
    return text


def model_markdown(label: str, r: dict[str, Any], onsets: Sequence[str]) -> list[str]:
    out = [
        f"### {label}: {r['source']}",
        "",
        f"Preset {r['preset']} (outputs {', '.join(r['outputs'])}), {r['patterns']} patterns, "
        f"sigma {r['sigma']:.4g}, N {r['window_N']}, p {r['horizon']}, J0 {r['J0']:.4g} "
        f"({r['threshold_rule']}), eps0 {r['eps0']:.4g}.",
        "",
        f"- False alarms on normal runs: {_fa(r['false_alarms_normal'])}; largest J/eps0 "
        f"on them {r['normal_max_J_over_eps0']}",
        f"- False alarms before a fault's onset: {_fa(r['false_alarms_pre_onset'])}",
        "",
        f"Table 1 (severity >= {TABLE1_MIN_SEVERITY}, abrupt and gradual pooled):",
        "",
        "| fault | runs | detected | median delay | isolation |",
        "|---|---:|---:|---:|---:|",
    ]
    for fault, c in r["table1"].items():
        out.append(
            f"| {fault} | {c['runs']} | {_pct(c['detection_rate'])} | "
            f"{_sec(c['median_delay_s'])} | {_pct(c['isolation_accuracy'])} |"
        )
    head = "| fault | severity |" + "".join(
        f" {o}: detected | {o}: delay | {o}: isolation |" for o in onsets
    )
    out += ["", "Per fault and severity (delay: median from onset; isolation: of detected):", ""]
    out += [head, "|---|---:|" + "---:|" * 3 * len(onsets)]
    for row in r["per_severity"]:
        cells = "".join(
            f" {_pct(row[o]['detection_rate'])} | {_sec(row[o]['median_delay_s'])} | "
            f"{_pct(row[o]['isolation_accuracy'])} |"
            for o in onsets
        )
        out.append(f"| {row['fault']} | {row['severity']:g} |{cells}")
    out += exercised_markdown(r["per_severity"])
    cols = r["confusion"]["columns"]
    for name, matrix in r["confusion"].items():
        if name == "columns":
            continue
        out += ["", f"Isolation confusion ({name}; rows: true fault, none = missed):", ""]
        out += ["| true \\ named | " + " | ".join(cols) + " |", "|---|" + "---:|" * len(cols)]
        for fault, counts in matrix.items():
            out.append(f"| {fault} | " + " | ".join(str(counts[c]) for c in cols) + " |")
    out.append("")
    return out


def markdown(result: dict[str, Any]) -> str:
    cfg = result["config"]
    rt = result["runtime_s"]
    lines = [
        "## Simulated evaluation (`monitor eval-sim`)",
        "",
        f"{result['plan']['fault_runs']} fault runs ({len(cfg['faults'])} faults x "
        f"{len(cfg['severities'])} severities x {len(cfg['onsets'])} onsets x {cfg['runs']} "
        f"runs; onset at {cfg['onset_s']:g} s, {cfg['duration_s']:g} s long, gradual ramps "
        f"{cfg['ramp_s']:g} s longer) and {result['plan']['normal_hours']:.2f} h of normal "
        f"runs, seeds disjoint from training. Run time {rt['total']:.0f} s "
        f"(simulation {rt['simulate']:.0f} s).",
        "",
    ]
    lines += summary_markdown(result["models"])
    for label, r in result["models"].items():
        lines += model_markdown(label, r, cfg["onsets"])
    return "\n".join(lines)


def summary_markdown(models: dict[str, dict[str, Any]]) -> list[str]:
    """Table 1 of every model side by side: detection / median delay / isolation per fault."""
    labels = list(models)
    out = [
        f"Table 1, all models (severity >= {TABLE1_MIN_SEVERITY}; detected / median delay / "
        "isolation accuracy; false alarms per hour of normal operation):",
        "",
        "| fault | " + " | ".join(labels) + " |",
        "|---|" + "---|" * len(labels),
    ]
    first = models[labels[0]]["table1"] if labels else {}
    for fault in first:
        cells = []
        for label in labels:
            c = models[label]["table1"][fault]
            cells.append(
                f"{_pct(c['detection_rate'])} / {_sec(c['median_delay_s'])} / "
                f"{_pct(c['isolation_accuracy'])}"
            )
        out.append(f"| {fault} | " + " | ".join(cells) + " |")
    fa = [_fa(models[label]["false_alarms_normal"]) for label in labels]
    out += ["| normal: false alarms | " + " | ".join(fa) + " |", ""]
    return out
