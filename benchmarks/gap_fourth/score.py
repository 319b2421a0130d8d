"""Score `monitor gap` on a set of the fourth plant's recordings, as a user runs it.

    python -m benchmarks.gap_fourth.score OUT --json F [--md F.md] [--jobs N] [--spend-blind]

Runs `python -m monitor gap --real OUT/<name>.csv --json OUT/gap/<name>.json` with this
interpreter for every recording of OUT/key.json (a diagnosis already in OUT/gap/ is reused,
so a run can resume; --jobs diagnoses in parallel), then compares each verdict with the
key. A set drawn from a blind seed is refused without --spend-blind."""

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
from typing import Any

from benchmarks.gap_fourth import effects
from benchmarks.gap_fourth.generate import refuse_blind


def diagnose(out: Path, name: str, monitor: str) -> dict[str, Any]:
    """One diagnosis (cached): its exit code, CPU and the `monitor` revision that ran it."""
    gap_dir = out / "gap"
    res, meta = gap_dir / f"{name}.json", gap_dir / f"{name}.run.json"
    if meta.exists():
        return json.loads(meta.read_text())
    tmp = gap_dir / f"{name}.part.json"
    cmd = [
        sys.executable,
        "-m",
        "monitor",
        "gap",
        "--real",
        str(out / f"{name}.csv"),
        "--json",
        str(tmp),
        "--quiet",
    ]
    t0 = time.monotonic()
    with open(gap_dir / f"{name}.stderr.txt", "w") as err:
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err)
        _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    run = {
        "name": name,
        "exit": proc.returncode,
        "wall_s": round(time.monotonic() - t0, 2),
        "cpu_s": round(usage.ru_utime + usage.ru_stime, 2),
        "monitor": monitor,
    }
    if tmp.exists():
        tmp.replace(res)
    meta.write_text(json.dumps(run) + "\n")
    return run


def sensor_signal(gap: dict[str, Any]) -> str | None:
    """The signal of a sensor_calibration verdict (params.sensor_calibration's keys)."""
    cal = (gap.get("params") or {}).get("sensor_calibration") or {}
    for key in cal:
        return key.split("_")[0]
    return None


def judge(entry: dict[str, Any], gap: dict[str, Any] | None) -> dict[str, Any]:
    """What the diagnosis said against what the key expects."""
    exp = entry["expected"]
    row = {
        "name": entry["name"],
        "effect": entry["effect"],
        "band": entry["tolerance_band"],
        "rodpos": entry["conditions"]["rodpos"],
        "warm_up": entry["conditions"]["warm_up"],
        "expected": exp["verdict"],
        "verdict": None,
        "first": None,
        "right": False,
    }
    if gap is None:
        return row
    row["verdict"] = gap.get("verdict")
    row["confidence"] = gap.get("confidence")
    sug = gap.get("suggestion") or []
    if sug:
        row["first"] = f"{sug[0].get('term')} {sug[0].get('signal')}"
    mech = gap.get("mechanism") or {}
    row["mechanism"] = mech.get("name")
    row["cause"] = mech.get("cause")
    if exp["verdict"] == "unexplained":
        row["right"] = (
            row["verdict"] == "unexplained"
            and bool(sug)
            and sug[0].get("term") == exp["term"]
            and sug[0].get("signal") == exp["signal"]
        )
    else:
        row["right"] = row["verdict"] == exp["verdict"]
    if entry["effect"] == "sensor_calibration":
        row["signal"] = sensor_signal(gap)
        row["right_signal"] = row["right"] and row["signal"] == exp["signal"]
    if entry["effect"] == "worn_pump":
        leak = (
            row["verdict"] == "unexplained"
            and bool(sug)
            and sug[0].get("term") == "leakage"
            and sug[0].get("signal") == "P->tank"
        )
        row["pump_leak_not_viscosity"] = leak and row["cause"] != "oil_viscosity"
        row["cause_wear"] = leak and row["cause"] == "wear"
    return row


def _frac(rows: list[dict], key: str = "right") -> str:
    return f"{sum(bool(r.get(key)) for r in rows)}/{len(rows)}"


def summarise(rows: list[dict], runs: list[dict]) -> dict[str, Any]:
    single = [r for r in rows if r["effect"] in effects.CATALOGUE]
    n_right = sum(r["right"] for r in single)
    fam = {e: _frac([r for r in single if r["effect"] == e]) for e in effects.CATALOGUE}
    cpu = [r["cpu_s"] for r in runs if r["exit"] == 0]
    worn = [r for r in rows if r["effect"] == "worn_pump"]
    return {
        "single_effects": {
            "right": n_right,
            "of": len(single),
            "pct": round(100.0 * n_right / max(len(single), 1), 1),
        },
        "families": fam,
        "healthy_none": _frac([r for r in rows if r["effect"] == "none"]),
        "sensor_on_right_signal": _frac(
            [r for r in rows if r["effect"] == "sensor_calibration"], "right_signal"
        ),
        "outside_unexplained_right_mechanism": _frac(
            [r for r in rows if r["effect"] in effects.OUTSIDE]
        ),
        "worn_pump_leak_not_viscosity": _frac(worn, "pump_leak_not_viscosity"),
        "worn_pump_cause_wear": _frac(worn, "cause_wear"),
        "median_cpu_s": round(statistics.median(cpu), 1) if cpu else None,
        "failed": [r["name"] for r in runs if r["exit"] != 0],
        "monitor_revisions": sorted({str(r.get("monitor")) for r in runs}),
    }


def which_monitor() -> dict[str, str]:
    """The `monitor` this interpreter runs: its path and, in a git tree, its commit."""
    code = "import monitor, os; print(os.path.dirname(os.path.abspath(monitor.__file__)))"
    path = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=False
    ).stdout.strip()
    git = ["git", "-C", path or ".", "describe", "--always", "--dirty"]
    rev = subprocess.run(git, capture_output=True, text=True, check=False).stdout.strip()
    last = ["git", "-C", path or ".", "log", "-1", "--format=%h %cs", "--", "."]
    changed = subprocess.run(last, capture_output=True, text=True, check=False).stdout.strip()
    return {
        "python": sys.executable,
        "monitor": path,
        "git": rev or "not in a git tree",
        "monitor_last_change": changed or "unknown",
    }


def markdown(summary: dict[str, Any], rows: list[dict], meta: dict[str, Any]) -> str:
    s = summary
    lines = [
        f"# monitor gap on the fourth plant, seed {meta['seed']} ({meta['set']})",
        "",
        f"monitor: {meta['which']['monitor']} ({meta['which']['git']}; monitor/ last "
        f"changed in {meta['which']['monitor_last_change']}); load {meta['load']}",
        "",
        f"- single effects top-1: {s['single_effects']['right']}/{s['single_effects']['of']}"
        f" ({s['single_effects']['pct']} %)",
        f"- healthy `none`: {s['healthy_none']}",
        f"- sensor calibration on the right signal: {s['sensor_on_right_signal']}",
        f"- out of catalogue `unexplained`, right mechanism first: "
        f"{s['outside_unexplained_right_mechanism']}",
        f"- worn pump (warm-up) named pump leakage, not viscosity: "
        f"{s['worn_pump_leak_not_viscosity']} (cause wear: {s['worn_pump_cause_wear']})",
        f"- median CPU per diagnosis: {s['median_cpu_s']} s",
        f"- diagnosed by: {', '.join(s['monitor_revisions'])}",
        "",
        "| family | right |",
        "|---|---|",
    ]
    lines += [f"| {e} | {v} |" for e, v in s["families"].items()]
    lines += [
        "",
        "| recording | effect | band | RodPos | warm-up | expected | verdict | "
        "suggestion first | right |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['name']} | {r['effect']} | {r['band']} | {r['rodpos']} | "
            f"{r['warm_up']} | {r['expected']} | {r['verdict']} | {r['first'] or ''} | "
            f"{'yes' if r['right'] else 'no'} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.gap_fourth.score", description=__doc__.split("\n\n")[0]
    )
    ap.add_argument("out", type=Path, help="a folder written by generate")
    ap.add_argument("--json", type=Path, required=True, help="write the scores here")
    ap.add_argument("--md", type=Path, help="also a Markdown table")
    ap.add_argument("--jobs", type=int, default=1, help="diagnoses in parallel")
    ap.add_argument("--spend-blind", action="store_true", help="score a blind draw")
    a = ap.parse_args(argv)
    key_path = a.out / "key.json"
    if not key_path.is_file():
        print(f"score: {key_path}: no key (write the set with generate)", file=sys.stderr)
        return 2
    key = json.loads(key_path.read_text())
    why = refuse_blind(int(key["seed"]), a.spend_blind, "score")
    if why:
        print(why, file=sys.stderr)
        return 2
    (a.out / "gap").mkdir(exist_ok=True)
    entries = key["recordings"]
    which = which_monitor()
    rev = f"{which['git']} (monitor/ {which['monitor_last_change']})"
    with ThreadPoolExecutor(max(a.jobs, 1)) as pool:
        runs = []
        for i, run in enumerate(pool.map(lambda e: diagnose(a.out, e["name"], rev), entries), 1):
            runs.append(run)
            print(f"\r{i}/{len(entries)} diagnosed", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    rows = []
    for e in entries:
        res = a.out / "gap" / f"{e['name']}.json"
        rows.append(judge(e, json.loads(res.read_text()) if res.exists() else None))
    meta = {
        "seed": key["seed"],
        "set": key["set"],
        "which": which,
        "load": " ".join(f"{x:.1f}" for x in os.getloadavg()),
    }
    summary = summarise(rows, runs)
    a.json.write_text(
        json.dumps({"meta": meta, "summary": summary, "recordings": rows, "runs": runs}, indent=1)
        + "\n"
    )
    if a.md:
        a.md.write_text(markdown(summary, rows, meta))
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
