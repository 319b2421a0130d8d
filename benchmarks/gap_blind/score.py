"""Score `monitor gap` (the public CLI) on a generated benchmark directory.

    python -m benchmarks.gap_blind.score OUT --json results.json [--jobs N]

JSON keys read from each `monitor gap` report: verdict, params.sensor_calibration,
suggestion[0].term, shrink.heldout_reduction.  A missing key fails loudly.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

KEYS_READ = (
    "verdict",
    "params.sensor_calibration",
    "suggestion[0].term",
    "shrink.heldout_reduction",
)


def run_gap(rec: Path, out_json: Path) -> dict:
    cmd = [
        sys.executable,
        "-m",
        "monitor",
        "gap",
        "--real",
        str(rec),
        "--json",
        str(out_json),
        "--quiet",
    ]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        return {"_error": f"exit {r.returncode}: {r.stderr.strip()[-300:]}"}
    return json.loads(out_json.read_text())


def _reduction(rep: dict):
    if "shrink" not in rep or "heldout_reduction" not in rep["shrink"]:
        raise KeyError("monitor gap JSON lacks shrink.heldout_reduction")
    v = rep["shrink"]["heldout_reduction"]
    if isinstance(v, dict):  # per signal: the mean over signals
        vals = [float(x) for x in v.values() if isinstance(x, (int, float))]
        return float(np.mean(vals)) if vals else None
    return None if v is None else float(v)


def judge(key: dict, rep: dict) -> dict:
    if "_error" in rep:
        return {"ok": False, "verdict": None, "error": rep["_error"]}
    if "verdict" not in rep:
        raise KeyError("monitor gap JSON lacks 'verdict'")
    verdict = rep["verdict"]
    row = {"verdict": verdict, "reduction": None}
    eff = key["effect"]
    if eff == "none":
        row["ok"] = verdict == "none"
    elif eff == "unexplained":
        sug = rep.get("suggestion") or []
        term = sug[0].get("term") if sug else None
        row["suggestion"] = term
        row["ok"] = verdict == "unexplained" and term == key["expected_suggestion"]
    else:
        row["ok"] = verdict == eff
        row["reduction"] = _reduction(rep) if verdict == eff else None
        if eff == "sensor_calibration":
            names = list((rep.get("params") or {}).get("sensor_calibration") or {})
            row["named"] = names
            row["signal_ok"] = any(n.split("_")[0] == key["signal"] for n in names)
            row["ok"] = row["ok"] and row["signal_ok"]
    return row


def summarise(rows: list[dict]) -> dict:
    def rate(sel):
        return {"right": sum(r["ok"] for r in sel), "n": len(sel)}

    single = [r for r in rows if r["effect"] not in ("none", "unexplained")]
    red = [r["reduction"] for r in single if r.get("reduction") is not None]
    return {
        "single_top1": rate(single),
        "healthy_none": rate([r for r in rows if r["effect"] == "none"]),
        "sensor_calibration_signal": rate([r for r in rows if r["effect"] == "sensor_calibration"]),
        "unexplained_suggestion": rate([r for r in rows if r["effect"] == "unexplained"]),
        "median_heldout_reduction": float(np.median(red)) if red else None,
        "keys_read": list(KEYS_READ),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.gap_blind.score", description=__doc__.splitlines()[0]
    )
    ap.add_argument("out", type=Path)
    ap.add_argument("--json", type=Path, required=True)
    ap.add_argument("--jobs", type=int, default=1)
    a = ap.parse_args(argv)
    key_path = a.out / "key.json"
    if not key_path.is_file():
        ap.error(f"{key_path}: no key.json (run benchmarks.gap_blind.generate first)")
    keys = json.loads(key_path.read_text())["recordings"]
    print(f"reading keys {', '.join(KEYS_READ)} from each monitor gap JSON", file=sys.stderr)
    (a.out / "gap").mkdir(exist_ok=True)

    def one(k):
        rep = run_gap(a.out / k["file"], a.out / "gap" / (k["file"] + ".json"))
        return {**k, **judge(k, rep)}

    rows = []
    try:
        with ThreadPoolExecutor(max(1, a.jobs)) as ex:
            for i, row in enumerate(ex.map(one, keys)):
                rows.append(row)
                print(
                    f"[{i + 1}/{len(keys)}] {row['file']}: {row['verdict']} "
                    f"{'ok' if row['ok'] else 'WRONG'}",
                    file=sys.stderr,
                    flush=True,
                )
    except KeyError as e:  # the public JSON contract changed: say so, do not score
        print(f"score: {e.args[0]}", file=sys.stderr)
        return 2
    summary = summarise(rows)
    a.json.write_text(json.dumps({"summary": summary, "rows": rows}, indent=1))
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
