"""Write what a user has: machines of two tolerance classes and a fleet, with an answer key.

    python -m benchmarks.detect_blind.generate --seed 1 --out /tmp/db1 [scale options]

OUT/types/<pm05|pm15>/<machine>/commissioning/commissioning.csv   20 min, oil 25 -> 45 degC
OUT/types/<pm05|pm15>/<machine>/normal/nNNN.csv                  normal logs, oil 30-60 degC
OUT/types/<pm05|pm15>/<machine>/fault/<fault>_<sev>_NN.csv        a fault from its onset
OUT/fleet/<machine>/commissioning/commissioning.log, logs/dayNN.log   candump (monitor encode)
OUT/key.json                                                     what every file holds
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from .records import Machine, RunSpec, record, write_csv

TYPES = {"pm05": 0.05, "pm15": 0.15}
FAULTS = ("piston_wear", "spool_wear", "spool_stroke")
STYLES = ("aggressive", "gentle", "fine", "mixed")


@dataclass(frozen=True)
class Scale:
    """How much data: per machine type, and the fleet."""

    machines_per_type: int = 1
    normal_hours: float = 2.0
    normal_log_min: float = 10.0
    severities: tuple[float, ...] = (0.3, 0.5)
    fault_runs: int = 1  # per fault and severity, per machine
    fault_log_min: float = 10.0
    commissioning_min: float = 20.0
    fleet_machines: int = 6
    fleet_days: int = 6
    fleet_log_min: float = 5.0
    fleet_wearing: int = 3  # the last machines wear over the days
    fleet_uncommissioned: int = 1  # healthy machines without a commissioning folder


def child_seed(*path: int) -> int:
    """A seed for one item, derived from the run's seed and the item's place."""
    return int(np.random.SeedSequence(list(path)).generate_state(1)[0])


def _normal_spec(rng: np.random.Generator, minutes: float, seed: int) -> RunSpec:
    start = rng.uniform(30.0, 60.0)
    end = float(np.clip(start + rng.uniform(-3.0, 3.0), 30.0, 60.0))
    return RunSpec(
        minutes * 60.0,
        str(rng.choice(STYLES)),
        start,
        end,
        payload=float(rng.uniform(0.7, 1.3)),
        seed=seed,
    )


def commissioning_spec(minutes: float, seed: int) -> RunSpec:
    """20 minutes of normal work while the oil warms from 25 to 45 degC."""
    return RunSpec(minutes * 60.0, "mixed", 25.0, 45.0, payload=1.0, seed=seed)


def type_plan(seed: int, scale: Scale) -> list[tuple[str, Machine, str, RunSpec]]:
    """(relative path, machine, kind, spec) for the machine-type part."""
    plan = []
    for ti, (tname, tol) in enumerate(TYPES.items()):
        for mi in range(scale.machines_per_type):
            m = Machine.draw(f"{tname}_m{mi}", tol, child_seed(seed, 1, ti, mi))
            base = f"types/{tname}/{m.name}"
            plan.append(
                (
                    f"{base}/commissioning/commissioning.csv",
                    m,
                    "commissioning",
                    commissioning_spec(scale.commissioning_min, child_seed(seed, 2, ti, mi)),
                )
            )
            rng = np.random.default_rng(child_seed(seed, 3, ti, mi))
            n_logs = int(np.ceil(scale.normal_hours * 60.0 / scale.normal_log_min))
            for k in range(n_logs):
                spec = _normal_spec(rng, scale.normal_log_min, child_seed(seed, 4, ti, mi, k))
                plan.append((f"{base}/normal/n{k:03d}.csv", m, "normal", spec))
            for fi, fault in enumerate(FAULTS):
                for si, sev in enumerate(scale.severities):
                    for r in range(scale.fault_runs):
                        spec = _normal_spec(
                            rng, scale.fault_log_min, child_seed(seed, 5, ti, mi, fi, si, r)
                        )
                        onset = float(rng.uniform(120.0, min(240.0, spec.duration_s / 2)))
                        spec = RunSpec(
                            spec.duration_s,
                            spec.style,
                            spec.temp_start_c,
                            spec.temp_end_c,
                            spec.payload,
                            fault,
                            sev,
                            onset,
                            spec.seed,
                        )
                        plan.append(
                            (f"{base}/fault/{fault}_{sev:.2f}_{r:02d}.csv", m, "fault", spec)
                        )
    return plan


def fleet_plan(seed: int, scale: Scale) -> list[tuple[str, Machine, str, RunSpec]]:
    """The fleet: machines +-10 %, the last `fleet_wearing` wearing from 0 to 0.6 over days."""
    plan = []
    n = scale.fleet_machines
    for mi in range(n):
        m = Machine.draw(f"F{mi + 1:02d}", 0.10, child_seed(seed, 11, mi))
        wear = mi >= n - scale.fleet_wearing
        uncommissioned = not wear and mi >= n - scale.fleet_wearing - scale.fleet_uncommissioned
        if not uncommissioned:
            plan.append(
                (
                    f"fleet/{m.name}/commissioning/commissioning.log",
                    m,
                    "commissioning",
                    commissioning_spec(scale.commissioning_min, child_seed(seed, 12, mi)),
                )
            )
        rng = np.random.default_rng(child_seed(seed, 13, mi))
        fault = FAULTS[(mi - (n - scale.fleet_wearing)) % len(FAULTS)] if wear else "normal"
        for d in range(scale.fleet_days):
            spec = _normal_spec(rng, scale.fleet_log_min, child_seed(seed, 14, mi, d))
            kind = "normal"
            if wear:
                sev = round(0.6 * d / max(scale.fleet_days - 1, 1), 3)
                spec = RunSpec(
                    spec.duration_s,
                    spec.style,
                    spec.temp_start_c,
                    spec.temp_end_c,
                    spec.payload,
                    fault,
                    sev,
                    0.0,
                    spec.seed,
                )
                kind = "wear"
            plan.append((f"fleet/{m.name}/logs/day{d:02d}.log", m, kind, spec))
    return plan


def _encode(csv: Path, log: Path) -> None:
    cmd = ["monitor", "encode", str(csv), "--out", str(log)]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"generate: {' '.join(cmd)} failed: {done.stderr.strip()}")


def write_item(out: Path, rel: str, machine: Machine, spec: RunSpec) -> None:
    """Simulate one recording and write it (CSV, or a candump log through `monitor encode`)."""
    path = out / rel
    rows = record(machine, spec)
    # Written aside and renamed: a file that exists is whole (a rerun skips it).
    csv = path.with_suffix(".tmp.csv")
    write_csv(csv, rows)
    if path.suffix == ".csv":
        csv.replace(path)
        return
    part = path.with_suffix(".tmp" + path.suffix)
    _encode(csv, part)
    csv.unlink()
    part.replace(path)


def generate(seed: int, out: Path, scale: Scale, progress=print) -> dict:
    """Write every recording and OUT/key.json; skips files a previous run finished."""
    plan = type_plan(seed, scale) + fleet_plan(seed, scale)
    key = {"seed": seed, "scale": asdict(scale), "files": [], "machines": {}}
    for i, (rel, m, kind, spec) in enumerate(plan):
        if not (out / rel).exists():
            write_item(out, rel, m, spec)
        entry = {
            "path": rel,
            "machine": m.name,
            "tolerance": m.tolerance,
            "kind": kind,
            **{k: v for k, v in asdict(spec).items() if k != "meta"},
        }
        key["files"].append(entry)
        key["machines"][m.name] = {"tolerance": m.tolerance, "params": m.params.tolist()}
        progress(f"generate: {i + 1}/{len(plan)} {rel}")
    (out / "key.json").write_text(json.dumps(key, indent=1))
    return key


def scale_arguments(ap: argparse.ArgumentParser) -> None:
    """The Scale's fields as options (shared with the scorer)."""
    d = Scale()
    ap.add_argument("--machines-per-type", type=int, default=d.machines_per_type)
    ap.add_argument(
        "--normal-hours",
        type=float,
        default=d.normal_hours,
        help="hours of normal logs per machine",
    )
    ap.add_argument("--normal-log-min", type=float, default=d.normal_log_min)
    ap.add_argument(
        "--severities",
        default=",".join(str(s) for s in d.severities),
        help="comma-separated fault severities (0.1-0.6)",
    )
    ap.add_argument("--fault-runs", type=int, default=d.fault_runs)
    ap.add_argument("--fault-log-min", type=float, default=d.fault_log_min)
    ap.add_argument("--fleet-machines", type=int, default=d.fleet_machines, help="0: no fleet")
    ap.add_argument("--fleet-days", type=int, default=d.fleet_days)
    ap.add_argument("--fleet-log-min", type=float, default=d.fleet_log_min)


def scale_from(args: argparse.Namespace) -> Scale:
    sev = tuple(float(s) for s in args.severities.split(",") if s.strip())
    if not sev or any(not 0.0 < s <= 1.0 for s in sev):
        raise SystemExit(f"--severities: {args.severities!r}: need values in (0, 1]")
    return Scale(
        args.machines_per_type,
        args.normal_hours,
        args.normal_log_min,
        sev,
        args.fault_runs,
        args.fault_log_min,
        fleet_machines=args.fleet_machines,
        fleet_days=args.fleet_days,
        fleet_log_min=args.fleet_log_min,
        fleet_wearing=min(3, args.fleet_machines),
        fleet_uncommissioned=1 if args.fleet_machines >= 5 else 0,
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m benchmarks.detect_blind.generate",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--out", type=Path, required=True)
    scale_arguments(ap)
    args = ap.parse_args(argv)
    generate(
        args.seed,
        args.out,
        scale_from(args),
        progress=lambda s: print(s, file=sys.stderr, flush=True),
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
