"""Draw a set of fifth-plant recordings and their key.

    python -m benchmarks.gap_fifth.generate OUT --seed S [--set small|full] [--pump pc|ls]
        [--duration 300]

Seeds 1-999 are for development; seeds 1000 and above are blind and refused without
--spend-blind. Prints only counts: the key (OUT/key.json) says what each recording holds.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from benchmarks.gap_fifth import effects as ef
from benchmarks.gap_fifth import record

BLIND_FROM = 1000
BANDS_PCT = (3.0, 12.0)
SENSOR_SIGNALS_FULL = ("PA", "PB", "PP", "QP", "RodPos", "PA")


def _expected(kind: str, name: str, signal: str | None) -> dict:
    if kind == "healthy":
        return {"verdict": "none"}
    if kind == "outside":
        term, where = ef.OUTSIDE[name]
        return {"verdict": "unexplained", "term": term, "signal": where}
    if name == "sensor_calibration":
        return {"verdict": name, "signal": signal}
    return {"verdict": name}


def plan(rng: np.random.Generator, which: str) -> list[dict]:
    """The recordings of a set, before names and seeds: kind, name, band, signal."""
    rows: list[dict] = []
    for i, effect in enumerate(ef.CATALOGUE):
        bands = [BANDS_PCT[i % 2]] if which == "small" else [b for b in BANDS_PCT for _ in "abc"]
        for k, band in enumerate(bands):
            signal = None
            if effect == "sensor_calibration":
                signal = (
                    str(rng.choice(["PA", "PB", "PP", "QP"]))
                    if which == "small"
                    else SENSOR_SIGNALS_FULL[k]
                )
            rows.append({"kind": "effect", "name": effect, "band_pct": band, "signal": signal})
    healthy = 1 if which == "small" else 3
    rows += [{"kind": "healthy", "name": "none", "band_pct": b} for b in BANDS_PCT] * healthy
    faults = list(ef.OUTSIDE)
    if which == "small":
        others = [str(x) for x in rng.choice(faults[1:], size=2, replace=False)]
        faults = ["worn_pump", *others]
    rows += [
        {"kind": "outside", "name": f, "band_pct": BANDS_PCT[k % 2]} for k, f in enumerate(faults)
    ]
    return rows


def draw(seed: int, which: str, pump: str = "pc") -> list[dict]:
    """Key entries: shuffled names, own seeds, RodPos on two thirds (always for a RodPos error);
    every entry names its pump (`pc` compensated, `ls` load sensing)."""
    rng = np.random.default_rng(seed)
    rows = plan(rng, which)
    n = len(rows)
    with_rod = np.zeros(n, dtype=bool)
    with_rod[: int(round(2 * n / 3))] = True
    rng.shuffle(with_rod)
    order = rng.permutation(n)
    entries = []
    for slot, idx in enumerate(order):
        row = dict(rows[idx])
        row["rodpos"] = bool(with_rod[slot]) or row.get("signal") == "RodPos"
        row["seed"] = int(rng.integers(1, 2**31 - 1))
        row["name_csv"] = f"s{seed}_{slot:02d}.csv"
        row["expected"] = _expected(row["kind"], row["name"], row.get("signal"))
        row["pump"] = pump
        entries.append(row)
    return entries


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.gap_fifth.generate")
    ap.add_argument("out", type=Path)
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--set", dest="which", choices=("small", "full"), default="full")
    ap.add_argument(
        "--pump",
        choices=("pc", "ls"),
        default="pc",
        help="base pump: pc pressure-compensated (the reference machine's law), ls load sensing",
    )
    ap.add_argument("--duration", type=float, default=300.0, help="seconds per recording")
    ap.add_argument("--spend-blind", action="store_true", help="allow a seed >= 1000")
    args = ap.parse_args(argv)
    if args.seed < 1:
        print(f"error: --seed {args.seed}: seeds start at 1", file=sys.stderr)
        return 2
    if args.seed >= BLIND_FROM and not args.spend_blind:
        print(
            f"error: --seed {args.seed} is blind (>= {BLIND_FROM}); it is drawn once, "
            "by the lead, with --spend-blind",
            file=sys.stderr,
        )
        return 2
    if not 40.0 <= args.duration <= 3600.0:
        print(f"error: --duration {args.duration}: 40..3600 s", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    entries = draw(args.seed, args.which, args.pump)
    for e in entries:
        content, info = record.build(e, args.duration)
        (args.out / e["name_csv"]).write_bytes(content)
        e.update(info)
    key = {
        "plant": "gap_fifth",
        "seed": args.seed,
        "set": args.which,
        "pump": args.pump,
        "duration_s": args.duration,
        "recordings": entries,
    }
    (args.out / "key.json").write_text(json.dumps(key, indent=1) + "\n")
    kinds = {k: sum(e["kind"] == k for e in entries) for k in ("effect", "healthy", "outside")}
    print(
        f"{len(entries)} recordings in {args.out} ({kinds['effect']} single effects, "
        f"{kinds['healthy']} healthy, {kinds['outside']} outside the catalogue; "
        f"{sum(e['rodpos'] for e in entries)} with RodPos)"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
