"""python -m benchmarks.gap_third.generate OUT --seed S [--set small|full]

Writes OUT/<name>.csv (contract CSVs) and OUT/key.json (the answer key).  Development seeds
are 1-999; a blind seed (>= 1000) is drawn with `secrets` once a change to the tool is fixed
and spent once (README.md)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from benchmarks.gap_third import machine
from benchmarks.gap_third.scenario import Scenario, record

SETS = {  # recordings per catalogue effect and tolerance class, healthy, out-of-catalogue
    "small": {"per_effect": {0.03: 1, 0.12: 0}, "healthy": 2, "ooc": 2},
    "full": {"per_effect": {0.03: 3, 0.12: 3}, "healthy": 6, "ooc": 6},
}


def scenarios(seed: int, kind: str, duration_s: float) -> list[Scenario]:
    """The recordings of one seed: which effect, tolerance, RodPos and warm-up each has."""
    rng = np.random.default_rng(seed)
    spec = SETS[kind]
    out: list[Scenario] = []

    def add(effect: str, tol: float, warmup: bool | None = None) -> None:
        k = len(out)
        wu = bool(rng.random() < 0.25) if warmup is None else warmup
        out.append(
            Scenario(
                name=f"s{seed}_{k:02d}_{effect}_{int(tol * 100)}pct",
                effect=effect,
                seed=seed * 1000 + k,
                tolerance=tol,
                rodpos=bool(k % 3 != 2),
                warmup=wu,
                duration_s=duration_s,
            )
        )

    for tol, n in spec["per_effect"].items():
        for effect in machine.CATALOGUE:
            for j in range(n):
                add(effect, tol, True if effect == "oil_viscosity" and j % 3 != 2 else None)
    for j in range(spec["healthy"]):
        add("none", (0.03, 0.12)[j % 2])
    ooc = list(machine.OUT_OF_CATALOGUE)
    if kind == "small":
        ooc = ["worn_pump", "compensator_low"]
    for j in range(spec["ooc"]):
        name = ooc[j % len(ooc)]
        add(name, (0.03, 0.12)[j % 2], True if name == "worn_pump" else None)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.gap_third.generate", description=__doc__.split("\n\n")[0]
    )
    ap.add_argument("out", type=Path)
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--set", dest="kind", choices=sorted(SETS), default="full")
    ap.add_argument("--duration", type=float, default=300.0, help="s per recording")
    ap.add_argument("--only", default="", help="comma-separated effects to keep")
    args = ap.parse_args(argv)
    if args.seed < 1:
        ap.error("--seed must be >= 1 (1-999 development, >= 1000 blind)")
    if args.duration < 60:
        ap.error("--duration must be at least 60 s")
    if args.out.exists() and not args.out.is_dir():
        ap.error(f"{args.out}: exists and is not a folder")
    args.out.mkdir(parents=True, exist_ok=True)
    keep = {e for e in args.only.split(",") if e}
    key = []
    for sc in scenarios(args.seed, args.kind, args.duration):
        if keep and sc.effect not in keep:
            continue
        key.append(record(sc, args.out / f"{sc.name}.csv"))
        print(f"{sc.name}: {sc.expected}", file=sys.stderr)
    meta = {"seed": args.seed, "blind": args.seed >= 1000, "set": args.kind, "recordings": key}
    (args.out / "key.json").write_text(json.dumps(meta, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
