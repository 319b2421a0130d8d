"""python -m benchmarks.gap_third.score OUT --json F [--jobs N] [--md F]

Runs `monitor gap --real REC --json ...` on every recording of OUT (as a user does) and
scores the verdicts against OUT/key.json: single effects top-1 (per family and tolerance
class), healthy `none`, sensor_calibration on the right signal, out-of-catalogue
`unexplained` with the right mechanism first in `suggestion`."""

from __future__ import annotations

import argparse
import importlib.util
import json
import subprocess
import sys
from collections import defaultdict
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path


def diagnose(csv: Path, out: Path) -> dict:
    """The tool's JSON for one recording (cached in OUT/gap/<name>.json)."""
    js = out / f"{csv.stem}.json"
    if not js.exists():
        proc = subprocess.run(
            [
                sys.executable,
                "-m",
                "monitor",
                "gap",
                "--real",
                str(csv),
                "--json",
                str(js),
                "--quiet",
            ],
            capture_output=True,
            text=True,
            check=False,
        )
        if proc.returncode != 0 or not js.exists():
            return {
                "verdict": f"error (exit {proc.returncode})",
                "error": (proc.stderr.strip().splitlines() or [""])[-1],
            }
    return json.loads(js.read_text())


def sensor_signal(rep: dict) -> str | None:
    """Which signal a sensor_calibration verdict names (params keys like PA_gain)."""
    keys = rep.get("params", {}).get("sensor_calibration", {})
    return next((k.split("_")[0] for k in keys), None) if isinstance(keys, dict) else None


def judge(entry: dict, rep: dict) -> dict:
    """One recording's outcome."""
    verdict = rep.get("verdict")
    sugg = rep.get("suggestion") or []
    first = sugg[0].get("term") if sugg else None
    row = {
        "name": entry["name"],
        "effect": entry["effect"],
        "tolerance": entry["tolerance"],
        "rodpos": entry["rodpos"],
        "expected": entry["expected"],
        "verdict": verdict,
        "member": rep.get("member"),
        "suggestion": first,
        "confidence": rep.get("confidence"),
    }
    ok = verdict == entry["expected"]
    if entry["effect"] == "sensor_calibration":
        row["signal_expected"], row["signal"] = entry["signal"], sensor_signal(rep)
        row["right_signal"] = ok and row["signal"] == entry["signal"]
    if entry["mechanism"]:
        row["mechanism"] = entry["mechanism"]
        ok = ok and first == entry["mechanism"]
    row["right"] = ok
    return row


def summarise(rows: list[dict]) -> dict:
    """Counts per class, effect family and tolerance."""

    def frac(rs: list[dict], key: str = "right") -> list[int]:
        return [sum(bool(r.get(key)) for r in rs), len(rs)]

    single = [r for r in rows if r["expected"] not in ("none", "unexplained")]
    fam: dict = defaultdict(list)
    for r in single:
        fam[f"{r['effect']} @{int(round(r['tolerance'] * 100))}%"].append(r)
    return {
        "single_top1": frac(single),
        "families": {k: frac(v) for k, v in sorted(fam.items())},
        "healthy_none": frac([r for r in rows if r["expected"] == "none"]),
        "sensor_right_signal": frac(
            [r for r in rows if r["effect"] == "sensor_calibration"], "right_signal"
        ),
        "out_of_catalogue": frac([r for r in rows if r["expected"] == "unexplained"]),
    }


def markdown(summary: dict, rows: list[dict]) -> str:
    s = summary
    lines = ["| class | right |", "|---|---|"]
    for label, key in (
        ("single effects top-1", "single_top1"),
        ("healthy `none`", "healthy_none"),
        ("sensor_calibration, right signal", "sensor_right_signal"),
        ("out of catalogue: `unexplained`, mechanism first", "out_of_catalogue"),
    ):
        lines.append(f"| {label} | {s[key][0]} of {s[key][1]} |")
    lines += ["", "| family @ tolerance | right |", "|---|---|"]
    lines += [f"| {k} | {v[0]} of {v[1]} |" for k, v in s["families"].items()]
    lines += [
        "",
        "| recording | expected | verdict | member | suggestion | RodPos | right |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        exp = (
            r["expected"]
            + (f" ({r['mechanism']})" if r.get("mechanism") else "")
            + (f" on {r['signal_expected']}" if r.get("signal_expected") else "")
        )
        got = str(r["verdict"]) + (f" on {r['signal']}" if r.get("signal") else "")
        lines.append(
            f"| {r['name']} | {exp} | {got} | {r['member'] or ''} | "
            f"{r['suggestion'] or ''} | {'yes' if r['rodpos'] else 'no'} | "
            f"{'yes' if r['right'] else 'no'} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.gap_third.score", description=__doc__.split("\n\n")[0]
    )
    ap.add_argument("out", type=Path, help="a folder written by generate")
    ap.add_argument("--json", type=Path, required=True)
    ap.add_argument("--md", type=Path, help="also write the Markdown table here")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument(
        "--cached-only",
        action="store_true",
        help="score only the recordings already diagnosed (OUT/gap/*.json)",
    )
    ap.add_argument(
        "--spend-blind",
        action="store_true",
        help="score a blind seed (once, after the change to the tool is fixed)",
    )
    args = ap.parse_args(argv)
    keyfile = args.out / "key.json"
    if not keyfile.exists():
        ap.error(f"{keyfile}: no answer key (run generate first)")
    key = json.loads(keyfile.read_text())
    if key["blind"] and not args.spend_blind:
        ap.error(f"seed {key['seed']} is blind: pass --spend-blind to spend it (once)")
    gap = args.out / "gap"
    gap.mkdir(exist_ok=True)
    entries = key["recordings"]
    if args.cached_only:
        entries = [e for e in entries if (gap / f"{e['name']}.json").exists()]
    with ThreadPoolExecutor(max(1, args.jobs)) as pool:
        reps = list(pool.map(lambda e: diagnose(args.out / f"{e['name']}.csv", gap), entries))
    rows = [judge(e, r) for e, r in zip(entries, reps, strict=True)]
    summary = summarise(rows)
    spec = importlib.util.find_spec("monitor")
    tool = {"python": sys.executable, "monitor": spec.origin if spec else None}
    args.json.write_text(
        json.dumps(
            {
                "seed": key["seed"],
                "set": key["set"],
                "tool": tool,
                "scored": len(rows),
                "recordings": len(key["recordings"]),
                "summary": summary,
                "rows": rows,
            },
            indent=1,
        )
    )
    md = markdown(summary, rows)
    if args.md:
        args.md.write_text(md)
    print(md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
