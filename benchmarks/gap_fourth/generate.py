"""Draw a set of recordings of the fourth plant and their key.

    python -m benchmarks.gap_fourth.generate OUT --seed S [--set small|full] [--duration 300]

Writes OUT/<name>.csv (contract CSVs, names in a shuffled order) and OUT/key.json; prints
only counts and paths, never what a recording holds. Seeds 1-999 are development seeds;
1000 and above are blind and refused without --spend-blind."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.gap_fourth import effects, record
from benchmarks.gap_fourth import params as pr

BLIND_FROM = 1000
BANDS = (0.03, 0.12)
SMALL_OUTSIDE = ("worn_pump", "piston_seal_bypass", "compensator_low")
CAL_SIGNALS = ("PP", "PA", "PB", "QP", "RodPos")


def plan(kind: str) -> list[tuple[str, float]]:
    """(effect, band) per recording: `full` 3 per catalogue effect and band, 6 healthy,
    one of each out-of-catalogue fault; `small` one per effect (bands alternating),
    2 healthy and three faults, the worn pump among them."""
    if kind == "full":
        out = [(e, b) for e in effects.CATALOGUE for b in BANDS for _ in range(3)]
        out += [("none", b) for b in BANDS for _ in range(3)]
        out += [(e, BANDS[i % 2]) for i, e in enumerate(effects.OUTSIDE)]
        return out
    out = [(e, BANDS[i % 2]) for i, e in enumerate(effects.CATALOGUE)]
    out += [("none", b) for b in BANDS]
    out += [(e, BANDS[(i + 1) % 2]) for i, e in enumerate(SMALL_OUTSIDE)]
    return out


def expected(effect: str, prm: dict[str, Any]) -> dict[str, Any]:
    if effect == "none":
        return {"verdict": "none"}
    if effect in effects.OUTSIDE:
        term, signal = effects.OUTSIDE[effect]
        return {"verdict": "unexplained", "term": term, "signal": signal}
    if effect == "sensor_calibration":
        return {"verdict": effect, "signal": prm["signal"]}
    return {"verdict": effect}


def _conditions(rng: np.random.Generator, effect: str, cal_signal: str | None) -> dict:
    warm_share = {"oil_viscosity": 0.67, "worn_pump": 1.0, "none": 0.34}.get(effect, 0.2)
    warm = bool(rng.uniform() < warm_share)
    ambient = round(float(rng.uniform(5.0, 25.0) if warm else rng.uniform(15.0, 32.0)), 2)
    start = ambient + float(rng.uniform(0.0, 5.0)) if warm else float(rng.uniform(43.0, 50.0))
    rodpos = bool(rng.uniform() >= 1.0 / 3.0) or cal_signal == "RodPos"
    return {
        "rodpos": rodpos,
        "warm_up": warm,
        "ambient_c": ambient,
        "oil_start_c": round(start, 2),
        "pump_mode": str(rng.choice(["matching", "full", "eco"], p=[0.5, 0.3, 0.2])),
        "rod0_mm": round(float(rng.uniform(50.0, 450.0)), 1),
        "zero_pct": {n: round(float(rng.uniform(-0.5, 0.5)), 4) for n in record.MEASURED},
        "temp_offset_c": round(float(rng.uniform(-0.5, 0.5)), 3),
    }


def draw(seed: int, kind: str, duration_s: float) -> list[dict[str, Any]]:
    """The key's entries (without the files)."""
    todo = plan(kind)
    master = np.random.default_rng(seed)
    names = [f"s{seed}_{i:02d}" for i in master.permutation(len(todo))]
    entries = []
    n_cal = 0
    children = np.random.SeedSequence(seed).spawn(len(todo))
    for (effect, band), name, child in zip(todo, names, children, strict=True):
        rng = np.random.default_rng(child)
        cal_signal = None
        if effect == "sensor_calibration":
            cal_signal = CAL_SIGNALS[(seed + n_cal) % len(CAL_SIGNALS)]
            n_cal += 1
            prm = effects._cal(rng, cal_signal)
        else:
            prm = effects.EFFECTS[effect][0](rng)
        entries.append(
            {
                "name": name,
                "effect": effect,
                "expected": expected(effect, prm),
                "params": prm,
                "tolerance_band": band,
                "tolerances": {k: round(v, 6) for k, v in pr.draw_tolerances(rng, band).items()},
                "conditions": _conditions(rng, effect, cal_signal),
                "noise_seed": int(rng.integers(0, 2**62)),
                "duration_s": float(duration_s),
            }
        )
    return sorted(entries, key=lambda e: e["name"])


def refuse_blind(seed: int, spend: bool, what: str) -> str | None:
    if seed >= BLIND_FROM and not spend:
        return (
            f"{what}: seed {seed} is a blind seed (>= {BLIND_FROM}); blind draws are "
            "spent once, by the lead: add --spend-blind to spend it"
        )
    if seed < 1:
        return f"{what}: seed {seed}: development seeds are 1-{BLIND_FROM - 1}"
    return None


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.gap_fourth.generate", description=__doc__.split("\n\n")[0]
    )
    ap.add_argument("out", type=Path, help="output folder (created)")
    ap.add_argument(
        "--seed",
        type=int,
        required=True,
        help="1-999 development, >= 1000 blind (needs --spend-blind)",
    )
    ap.add_argument("--set", dest="kind", choices=("small", "full"), default="small")
    ap.add_argument("--duration", type=float, default=300.0, help="seconds per recording")
    ap.add_argument("--spend-blind", action="store_true", help="draw a blind seed")
    a = ap.parse_args(argv)
    why = refuse_blind(a.seed, a.spend_blind, "generate")
    if why:
        print(why, file=sys.stderr)
        return 2
    if a.duration < 60.0:
        print(f"generate: --duration {a.duration}: at least 60 s", file=sys.stderr)
        return 2
    a.out.mkdir(parents=True, exist_ok=True)
    entries = draw(a.seed, a.kind, a.duration)
    t0 = time.process_time()
    for i, e in enumerate(entries, 1):
        record.build(e, a.out)
        print(f"\r{i}/{len(entries)} recordings", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    key = {
        "plant": "gap_fourth",
        "seed": a.seed,
        "set": a.kind,
        "blind": a.seed >= BLIND_FROM,
        "duration_s": a.duration,
        "recordings": entries,
    }
    (a.out / "key.json").write_text(json.dumps(key, indent=1) + "\n")
    print(
        f"{len(entries)} recordings and key.json in {a.out} ({time.process_time() - t0:.0f} s CPU)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
