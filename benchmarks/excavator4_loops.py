"""The whole machine's four loops on their shipped models: false alarms per hour per loop on
simulated normal operation, and which loops alarm on a fault of one loop (or of the pump).

    python benchmarks/excavator4_loops.py --normal 401-412 --faulty 501 --out runs/

Normal runs: ``monitor simulate --machine excavator4`` mixed duty cycles of 600 s on the
``--normal`` seeds; faulty runs: the same on each ``--faulty`` seed with one fault of
``FAULTS`` at each severity of ``--severity`` (e.g. ``--severity 0.5 0.3``) from 120 s.
Each run is judged per loop as ``monitor detect --loop NAME --config CONFIG`` judges it
(``--config``: default the shipped config and its models); ``--loops`` judges only those
(a retrained loop's runs without the others'); ``--faults`` the faults (default ``FAULTS``; any
``LOOP.FAULT`` of ``monitor simulate --machine excavator4``).  Prints one line per run and
loop, then the table.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

from monitor.config.settings import load_config
from monitor.detection.offline import detect
from monitor.model.modelfile import load_model
from monitor.offline.recordings import loop_recordings
from monitor.resources import resource_path

DURATION_S = 600
ONSET_S = 120
FAULTS = (
    "stick.piston_wear",
    "stick.spool_wear",
    "stick.spool_stroke",
    "boom.spool_wear",
    "swing.motor_leakage",
    "pump.pump_wear",
)


def _seeds(text: str) -> list[int]:
    """``A-B`` (or ``A``) as the seeds A..B; ``none`` as no seeds (only faulty runs)."""
    if text == "none":
        return []
    lo, _, hi = text.partition("-")
    try:
        seeds = list(range(int(lo), int(hi or lo) + 1))
    except ValueError:
        raise argparse.ArgumentTypeError(f"seeds A-B expected, got {text!r}") from None
    if not seeds:
        raise argparse.ArgumentTypeError(f"seeds A-B with A <= B expected, got {text!r}")
    return seeds


def _simulate(out: Path, seed: int, fault: str | None, severity: float) -> Path:
    name = f"{fault}_{severity}_{seed}.csv" if fault else f"normal_{seed}.csv"
    path = out / name
    if not path.exists():
        cmd = [sys.executable, "-m", "monitor", "simulate", "--machine", "excavator4"]
        cmd += ["--duration", str(DURATION_S), "--seed", str(seed), "--out", str(path)]
        if fault:
            cmd += ["--fault", f"{fault}:{severity}@{ONSET_S}"]
        subprocess.run(cmd, check=True, capture_output=True)
    return path


def _judge(path: Path, cfg, models) -> dict[str, dict]:
    """Every loop's ``monitor detect --loop`` summary of one run (the file read once)."""
    recs = loop_recordings(path, cfg, list(models))
    return {
        name: detect(models[name], rec, cfg.alarm, cfg.horizon, gating=cfg.gating).summary
        for name, rec in recs.items()
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--normal", type=_seeds, default="401-412", help="seeds of normal runs, A-B, or none"
    )
    ap.add_argument("--faulty", type=_seeds, default="501", help="seeds of faulty runs, A-B")
    ap.add_argument("--severity", type=float, nargs="+", default=[0.5])
    ap.add_argument("--out", type=Path, required=True, help="folder for the simulated runs")
    ap.add_argument(
        "--config",
        type=Path,
        default=resource_path("config", "excavator4.yaml"),
        help="the whole machine's config whose loop models are judged (default: shipped)",
    )
    ap.add_argument("--loops", nargs="+", metavar="NAME", help="judge only these loops")
    ap.add_argument(
        "--faults", nargs="+", metavar="LOOP.FAULT", default=list(FAULTS), help="default FAULTS"
    )
    args = ap.parse_args()
    cfg = load_config(args.config)
    names = [lc.name for lc in cfg.monitored_loops]
    unknown = sorted(set(args.loops or ()) - set(names))
    if unknown:
        ap.error(f"--loops {' '.join(unknown)}: {args.config} has loops {', '.join(names)}")
    args.out.mkdir(parents=True, exist_ok=True)
    models = {
        lc.name: load_model(lc.model)
        for lc in cfg.monitored_loops
        if not args.loops or lc.name in args.loops
    }
    loops = list(models)
    alarms = {name: 0 for name in loops}
    sensor = {name: 0 for name in loops}
    hours = 0.0
    for seed in args.normal:
        judged = _judge(_simulate(args.out, seed, None, 0.0), cfg, models)
        hours += DURATION_S / 3600
        line = []
        for name, s in judged.items():
            alarms[name] += bool(s["alarm"])
            sensor[name] += bool(s["sensor_checks"])
            line.append(f"{name} {s['verdict']} (level {s['max_level'] or 0:.2f})")
        print(f"normal seed {seed}: " + ", ".join(line), flush=True)
    print(f"\nnormal: {hours:.1f} h per loop")
    for name in loops if hours else ():
        print(
            f"  {name}: {alarms[name]} runs with an alarm ({alarms[name] / hours:.2f}/h), "
            f"{sensor[name]} with a sensor finding"
        )
    print()
    for severity in args.severity:
        for fault in args.faults:
            for seed in args.faulty:
                judged = _judge(_simulate(args.out, seed, fault, severity), cfg, models)
                raised = [
                    f"{n} from {s['first_alarm_t']:.0f} s" for n, s in judged.items() if s["alarm"]
                ]
                print(f"{fault}:{severity} seed {seed}: alarms {', '.join(raised) or 'none'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
