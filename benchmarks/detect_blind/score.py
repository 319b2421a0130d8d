"""Score the monitor on the outsider's plant, as a user works: the CLI and its defaults.

    python -m benchmarks.detect_blind.score --seed 1 --work /tmp/db1 --json r.json --md r.md

Per machine: `monitor train` on its 20 min commissioning run (defaults), `monitor detect
--summary` on every normal and fault log; the fleet: `monitor fleet run --workers 1`.
Reports hydraulic false alarms per hour with the 95 % upper bound, sensor-fault false alarms,
detection, median delay and isolation by fault and severity, per machine type (+-5 %, +-15 %),
and the fleet's verdicts. Seeds 1-999 are development seeds; blind seeds are drawn once with
`secrets` after a change is fixed (README.md).
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
from pathlib import Path

from . import metrics, report
from .generate import FAULTS, TYPES, generate, scale_arguments, scale_from

DEV_SEEDS_MAX = 999


def monitor_cmd() -> list[str]:
    """The user's `monitor` (the one on PATH), or this interpreter's."""
    exe = shutil.which("monitor")
    return [exe] if exe else [sys.executable, "-m", "monitor"]


def run_monitor(args: list[str], log: Path) -> int:
    """Run a monitor command, its output to `log`; its exit code."""
    log.parent.mkdir(parents=True, exist_ok=True)
    with log.open("w") as fh:
        return subprocess.run(monitor_cmd() + args, stdout=fh, stderr=subprocess.STDOUT).returncode


def alarm_episodes(events: Path) -> int:
    """Hydraulic alarms in a detect run: entries into the fault state."""
    n, prev = 0, None
    if not events.exists():
        return 0
    for line in events.read_text().splitlines():
        try:
            state = json.loads(line).get("state")
        except ValueError:
            continue
        if state == "fault" and prev != "fault":
            n += 1
        if state is not None:
            prev = state
    return n


def train(data: Path, work: Path, machine_dir: str, resume: bool) -> tuple[Path, int]:
    model = work / "models" / (machine_dir.replace("/", "_") + ".npz")
    if resume and model.exists():
        return model, 0
    comm = sorted((data / machine_dir / "commissioning").glob("*.csv"))
    rc = run_monitor(
        ["train", *map(str, comm), "--out", str(model)], model.with_suffix(".train.txt")
    )
    return model, rc


def detect(data: Path, work: Path, entry: dict, model: Path, resume: bool) -> dict:
    """One `monitor detect --summary` and what it says, with the file's key."""
    base = work / "detect" / entry["path"]
    summary, events = base.with_suffix(".summary.json"), base.with_suffix(".events.jsonl")
    rc = 0
    if not (resume and summary.exists()):
        rc = run_monitor(
            [
                "detect",
                str(data / entry["path"]),
                "--model",
                str(model),
                "--summary",
                str(summary),
                "--events",
                str(events),
            ],
            base.with_suffix(".detect.txt"),
        )
    s = json.loads(summary.read_text()) if summary.exists() else {}
    return {
        **entry,
        "rc": rc,
        "alarm": bool(s.get("alarm")),
        "verdict": s.get("verdict"),
        "first_alarm_t": s.get("first_alarm_t"),
        "fault_named": s.get("fault"),
        "sensor_fault": bool(s.get("sensor_fault")),
        "judged_s": s.get("judged_s") or 0.0,
        "max_J": s.get("max_J"),
        "threshold": s.get("threshold"),
        "episodes": s.get("alarm_episodes", alarm_episodes(events)),
        "not_judged_why": s.get("not_judged_why"),
        "out_of_range_signals": s.get("out_of_range_signals"),
        "error": None if s else f"exit {rc}",
    }


def score_types(data: Path, work: Path, key: dict, resume: bool, progress) -> dict:
    """Train and detect per machine; the figures per machine type."""
    out = {}
    for tname in TYPES:
        entries = [e for e in key["files"] if e["path"].startswith(f"types/{tname}/")]
        machines = sorted({e["path"].split("/")[2] for e in entries})
        rows, trains = [], {}
        for m in machines:
            model, rc = train(data, work, f"types/{tname}/{m}", resume)
            trains[m] = rc
            progress(f"score: trained {tname}/{m} (exit {rc})")
            for e in entries:
                if e["machine"] == m and e["kind"] != "commissioning" and rc == 0:
                    rows.append(detect(data, work, e, model, resume))
                    progress(f"score: {e['path']}: {rows[-1]['verdict']}")
        out[tname] = summarise_type(rows, trains)
    return out


def summarise_type(rows: list[dict], trains: dict) -> dict:
    normal = [r for r in rows if r["kind"] == "normal"]
    hours = sum(r["judged_s"] for r in normal) / 3600.0
    episodes = sum(r["episodes"] if r["episodes"] else int(r["alarm"]) for r in normal)
    faults = {}
    for fault in FAULTS:
        for sev in sorted({r["severity"] for r in rows if r["fault"] == fault}):
            runs = [r for r in rows if r["fault"] == fault and r["severity"] == sev]
            faults[f"{fault}@{sev:.2f}"] = metrics.detection(runs)
    detected = [
        r
        for r in rows
        if r["kind"] == "fault" and r["alarm"] and (r["first_alarm_t"] or 0) >= r["onset_s"]
    ]
    return {
        "train_exit": trains,
        "logs": len(rows),
        "normal_logs": len(normal),
        "normal_hours_recorded": sum(r["duration_s"] for r in normal) / 3600.0,
        "false_alarms": metrics.rate_per_hour(episodes, hours),
        "normal_logs_alarming": sum(r["alarm"] for r in normal),
        "normal_not_judged": sum(metrics.unjudged(r) for r in normal),
        "sensor_fault_logs": sum(r["sensor_fault"] for r in rows),
        "sensor_fault_normal_logs": sum(r["sensor_fault"] for r in normal),
        "errors": sum(r["error"] is not None for r in rows),
        "faults": faults,
        "isolation_all": (
            sum(r["fault_named"] == r["fault"] for r in detected) / len(detected)
            if detected
            else None
        ),
        "rows": rows,
    }


def score_fleet(data: Path, work: Path, key: dict, resume: bool, progress) -> dict | None:
    """`monitor fleet run --workers 1` on the fleet folder and its verdicts against the key."""
    if not (data / "fleet").exists():
        return None
    import pandas as pd

    results = work / "fleet_results"
    table = results / "logs.parquet"
    rc = 0
    if not (resume and table.exists()):
        shutil.rmtree(results, ignore_errors=True)
        rc = run_monitor(
            ["fleet", "run", str(data / "fleet"), "--out", str(results), "--workers", "1"],
            work / "fleet_run.txt",
        )
        progress(f"score: fleet run exit {rc}")
    if not table.exists():
        return {"exit": rc, "error": "no logs.parquet"}
    df = pd.read_parquet(table)
    return report.fleet_summary(df, key, rc)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.detect_blind.score",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    ap.add_argument(
        "--seed",
        type=int,
        required=True,
        help=f"1-{DEV_SEEDS_MAX}: development; larger: a blind seed (README.md)",
    )
    ap.add_argument("--work", type=Path, required=True, help="data and results go here")
    ap.add_argument("--json", type=Path, required=True)
    ap.add_argument("--md", type=Path, required=True)
    ap.add_argument(
        "--resume", action="store_true", help="reuse models and summaries already in --work"
    )
    scale_arguments(ap)
    args = ap.parse_args(argv)
    scale = scale_from(args)

    def progress(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    data = args.work / "data"
    key = generate(args.seed, data, scale, progress)
    result = {
        "seed": args.seed,
        "blind": args.seed > DEV_SEEDS_MAX,
        "scale": key["scale"],
        "types": score_types(data, args.work, key, args.resume, progress),
        "fleet": score_fleet(data, args.work, key, args.resume, progress),
    }
    args.json.write_text(json.dumps(result, indent=1, default=str))
    args.md.write_text(report.markdown(result))
    print(args.md.read_text())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
