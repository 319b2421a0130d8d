"""Pool scored runs of several seeds into one table.

    python -m benchmarks.detect_blind.combine s1.json s2.json s3.json --md pooled.md

Rows of each machine type are pooled (the false-alarm hours add up, the fault runs too); the
fleet is taken from the runs that have one.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from . import report
from .score import summarise_type


def combine(results: list[dict]) -> dict:
    types: dict[str, dict] = {}
    for res in results:
        for tname, t in res["types"].items():
            pooled = types.setdefault(tname, {"rows": [], "trains": {}})
            pooled["rows"] += t["rows"]
            pooled["trains"].update(
                {f"seed{res['seed']}/{m}": rc for m, rc in t["train_exit"].items()}
            )
    fleets = [r["fleet"] for r in results if r.get("fleet")]
    return {
        "seed": "+".join(str(r["seed"]) for r in results),
        "blind": any(r["blind"] for r in results),
        "types": {k: summarise_type(v["rows"], v["trains"]) for k, v in types.items()},
        "fleet": fleets[0] if len(fleets) == 1 else None,
        "fleets": fleets,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.detect_blind.combine",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    ap.add_argument("results", nargs="+", type=Path, help="JSON files the scorer wrote")
    ap.add_argument("--md", type=Path)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    pooled = combine([json.loads(p.read_text()) for p in args.results])
    text = report.markdown(pooled)
    if args.md:
        args.md.write_text(text)
    if args.json:
        args.json.write_text(json.dumps(pooled, indent=1, default=str))
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
