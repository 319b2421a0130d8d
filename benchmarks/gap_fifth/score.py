"""Score `monitor gap` on a set of fifth-plant recordings.

    python -m benchmarks.gap_fifth.score OUT --json F [--md F.md] [--jobs N] [--spend-blind]

Runs `python -m monitor gap --real OUT/<name>.csv --json OUT/gap/<name>.json --quiet` with
this interpreter (the `monitor` it imports is the one scored: its path and git revision are
in the scores), keeps each diagnosis in OUT/gap/ (a run resumes where it stopped), and
compares each verdict with the key's `expected`.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from benchmarks.gap_fifth import effects as ef
from benchmarks.gap_fifth.generate import BLIND_FROM

SIGNALS = ("PP", "PA", "PB", "QP", "RodPos")


def diagnose(out: Path, name: str) -> dict:
    """One `monitor gap` run (or the one kept from before): exit code, CPU and wall seconds."""
    csv = out / name
    dest = out / "gap" / (csv.stem + ".json")
    done = out / "gap" / (csv.stem + ".run.json")
    if done.exists() and dest.exists():
        return json.loads(done.read_text())
    cmd = [sys.executable, "-m", "monitor", "gap", "--real", str(csv), "--json", str(dest)]
    log = out / "gap" / (csv.stem + ".stderr.txt")
    start = time.monotonic()
    with open(log, "wb") as err:
        proc = subprocess.Popen([*cmd, "--quiet"], stdout=subprocess.DEVNULL, stderr=err)
        _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    run = {
        "exit": proc.returncode,
        "cpu_s": round(usage.ru_utime + usage.ru_stime, 2),
        "wall_s": round(time.monotonic() - start, 2),
        "stderr": log.read_text(errors="replace")[-2000:],
    }
    if proc.returncode == 0:
        done.write_text(json.dumps(run) + "\n")
    return run


def suggestion_first(gap: dict) -> tuple[str | None, str | None]:
    sug = gap.get("suggestion") or []
    if not sug:
        return None, None
    return sug[0].get("term"), sug[0].get("signal")


def sensor_signal(gap: dict) -> str | None:
    """The signal of params.sensor_calibration's keys (PA_gain -> PA)."""
    params = gap.get("params") or {}
    cal = params.get("sensor_calibration")
    if not isinstance(cal, dict) or not cal:  # the same names, flat in params
        cal = {k: v for k, v in params.items() if k.split("_")[0] in SIGNALS and "_" in k}
    return sorted({k.split("_")[0] for k in cal})[0] if cal else None


def judge(entry: dict, gap: dict | None) -> dict:
    """One recording's verdict against the key."""
    exp = entry["expected"]
    row = {"name": entry["name_csv"], "kind": entry["kind"], "truth": entry["name"]}
    if gap is None:
        return {**row, "verdict": "failed", "right": False}
    verdict = gap.get("verdict")
    row["verdict"] = verdict
    row["right"] = verdict == exp["verdict"]
    if entry["kind"] == "outside":
        term, signal = suggestion_first(gap)
        row["suggestion"] = f"{term} {signal}"
        row["right"] = row["right"] and (term, signal) == (exp["term"], exp["signal"])
        if entry["name"] == "worn_pump":
            mech = gap.get("mechanism") or {}
            cause = mech.get("cause")
            leak = (term, signal) == ("leakage", "P->tank") or "pump leak" in str(
                mech.get("name", "")
            )
            row["pump_leakage"] = bool(leak)
            row["cause"] = cause
            row["not_viscosity"] = (
                bool(leak) and cause != "oil_viscosity" and (verdict != "oil_viscosity")
            )
    if exp.get("signal") and entry["name"] == "sensor_calibration":
        row["signal"] = sensor_signal(gap)
        row["right_signal"] = row["right"] and row["signal"] == exp["signal"]
    return row


def summarise(rows: list[dict], runs: dict[str, dict]) -> dict:
    effects = [r for r in rows if r["kind"] == "effect"]
    per_family = {
        f: f"{sum(r['right'] for r in effects if r['truth'] == f)}/"
        f"{sum(r['truth'] == f for r in effects)}"
        for f in ef.CATALOGUE
    }
    healthy = [r for r in rows if r["kind"] == "healthy"]
    sensor = [r for r in effects if r["truth"] == "sensor_calibration"]
    outside = [r for r in rows if r["kind"] == "outside"]
    worn = [r for r in outside if r["truth"] == "worn_pump"]
    cpu = [r["cpu_s"] for r in runs.values() if r.get("exit") == 0]
    n_right = sum(r["right"] for r in effects)
    return {
        "single_effects": f"{n_right}/{len(effects)}",
        "single_effects_pct": round(100.0 * n_right / max(len(effects), 1), 1),
        "families": per_family,
        "healthy_none": f"{sum(r['right'] for r in healthy)}/{len(healthy)}",
        "sensor_right_signal": f"{sum(r.get('right_signal', False) for r in sensor)}/{len(sensor)}",
        "outside_unexplained_right_term": f"{sum(r['right'] for r in outside)}/{len(outside)}",
        "worn_pump_leak_not_viscosity": f"{sum(r.get('not_viscosity', False) for r in worn)}/"
        f"{len(worn)}",
        "worn_pump_cause_wear": f"{sum(r.get('cause') == 'wear' for r in worn)}/{len(worn)}",
        "median_cpu_s": round(statistics.median(cpu), 1) if cpu else None,
        "failed": [n for n, r in runs.items() if r.get("exit") != 0],
    }


def which_monitor() -> dict:
    """The `monitor` this interpreter imports: path and git revision."""
    code = "import monitor, os; print(os.path.dirname(monitor.__file__))"
    path = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=False
    ).stdout.strip()
    rev = subprocess.run(
        ["git", "-C", path or ".", "rev-parse", "--short", "HEAD"],
        capture_output=True,
        text=True,
        check=False,
    ).stdout.strip()
    return {"path": path, "git": rev or None}


def markdown(summary: dict, rows: list[dict]) -> str:
    lines = [
        f"# monitor gap on the fifth plant, seed {summary['seed']} ({summary['set']}, "
        f"pump {summary['pump']})",
        "",
    ]
    for key in ("single_effects", "single_effects_pct", "healthy_none", "sensor_right_signal",
                "outside_unexplained_right_term", "worn_pump_leak_not_viscosity",
                "worn_pump_cause_wear", "median_cpu_s", "load_average", "monitor"):  # fmt: skip
        lines.append(f"- {key}: {summary[key]}")
    lines += ["", "| family | right |", "|---|---|"]
    lines += [f"| {f} | {n} |" for f, n in summary["families"].items()]
    lines += ["", "| recording | kind | truth | verdict | right | detail |", "|---" * 6 + "|"]
    for r in rows:
        detail = r.get("suggestion") or r.get("signal") or ""
        if "cause" in r:
            detail += f" cause {r['cause']}"
        lines.append(
            f"| {r['name']} | {r['kind']} | {r['truth']} | {r['verdict']} | "
            f"{'yes' if r['right'] else 'no'} | {detail} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.gap_fifth.score")
    ap.add_argument("out", type=Path)
    ap.add_argument("--json", type=Path, required=True)
    ap.add_argument("--md", type=Path)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--spend-blind", action="store_true")
    args = ap.parse_args(argv)
    key_path = args.out / "key.json"
    if not key_path.is_file():
        print(f"error: {key_path}: no key (run generate first)", file=sys.stderr)
        return 2
    key = json.loads(key_path.read_text())
    if key["seed"] >= BLIND_FROM and not args.spend_blind:
        print(
            f"error: {key_path}: seed {key['seed']} is blind (>= {BLIND_FROM}); "
            "scored once, by the lead, with --spend-blind",
            file=sys.stderr,
        )
        return 2
    if args.jobs < 1:
        print(f"error: --jobs {args.jobs}: at least 1", file=sys.stderr)
        return 2
    (args.out / "gap").mkdir(exist_ok=True)
    entries = key["recordings"]
    with ThreadPoolExecutor(args.jobs) as pool:
        runs = dict(
            zip(
                [e["name_csv"] for e in entries],
                pool.map(lambda e: diagnose(args.out, e["name_csv"]), entries),
                strict=True,
            )
        )
    rows = []
    for e in entries:
        dest = args.out / "gap" / (Path(e["name_csv"]).stem + ".json")
        ok = runs[e["name_csv"]]["exit"] == 0 and dest.is_file()
        rows.append(judge(e, json.loads(dest.read_text()) if ok else None))
    summary = summarise(rows, runs)
    summary.update(
        seed=key["seed"],
        set=key["set"],
        pump=key.get("pump", "ls"),  # keys from before the compensated pump: load sensing
        load_average=[round(x, 2) for x in os.getloadavg()],
        monitor=which_monitor(),
    )
    args.json.write_text(json.dumps({"summary": summary, "recordings": rows}, indent=1) + "\n")
    if args.md:
        args.md.write_text(markdown(summary, rows))
    print(
        f"single effects {summary['single_effects']}, healthy none {summary['healthy_none']}, "
        f"outside {summary['outside_unexplained_right_term']}, "
        f"failed {len(summary['failed'])}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
