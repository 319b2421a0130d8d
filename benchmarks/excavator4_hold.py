"""Can the hold statistic H see a worn stick piston on the whole machine?  H on a stick
section model's residuals, fitted on held-out normal runs, judged on normal and faulty runs.

    python benchmarks/excavator4_hold.py --model config/stick_excavator4.model.npz \\
        --held 201-202 --normal 401-412 --faulty 501-508 --out runs/

H is fitted as ``monitor train --hold on`` fits it (``monitor.model.hold``: the mean residual
of PA and PB over settled holds of a 60 s window, scaled by the held-out runs' largest, the
threshold twice the held-out largest), but without the end-stop estimate, which whole-machine
work cannot give (it needs the rod run from stop to stop).  Two sets of counted holds:

- ``holds``: every settled hold of the stick's lever, as H counts them;
- ``holds at standby``: only while the pump idles at its standby pressure (PP below the
  load-sensing margin plus 10 bar): no section is working against a load, so nothing but the
  stick's own chambers moves its held pressures.

Runs: ``monitor simulate --machine excavator4`` mixed work of 600 s; the faulty ones with
``stick.piston_wear`` at ``--severity`` from 120 s.  Prints, per set of holds, the largest H
over h0 of every held-out run, the largest over the normal runs (above 1: a false alarm), and
per faulty run its largest after the onset and when H first passes h0.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import numpy as np

from monitor.config.settings import load_config
from monitor.detection.offline import gated_residuals
from monitor.errors import InputFileError
from monitor.model.hold import HoldModel, fit_hold_scale, hold_flags, hold_series
from monitor.model.modelfile import load_model
from monitor.offline.recordings import loop_recording
from monitor.resources import resource_path

DURATION_S = 600
ONSET_S = 120
LOOP = "stick"
STANDBY_ABOVE_MARGIN_BAR = 10.0
WINDOW_N, MIN_COUNT, SETTLE_N = 6000, 300, 200  # H's defaults (monitor train --hold on)


def _seeds(text: str) -> list[int]:
    lo, _, hi = text.partition("-")
    return list(range(int(lo), int(hi or lo) + 1))


def _simulate(out: Path, kind: str, seed: int, severity: float) -> Path:
    name = f"{kind}_{severity:g}_{seed}" if kind == "piston_wear" else f"{kind}_{seed}"
    path = out / f"{name}.csv"
    if not path.exists():
        cmd = [sys.executable, "-m", "monitor", "simulate", "--machine", "excavator4"]
        cmd += ["--duration", str(DURATION_S), "--seed", str(seed), "--out", str(path)]
        if kind == "piston_wear":
            cmd += ["--fault", f"{LOOP}.piston_wear:{severity}@{ONSET_S}"]
        subprocess.run(cmd, check=True, capture_output=True)
    return path


def _run(path: Path, cfg, model, standby_bar: float) -> dict[str, np.ndarray]:
    """The stick's residuals, time and both sets of counted holds of one run."""
    rec = loop_recording(path, cfg, LOOP)
    e = gated_residuals(model, rec, cfg.alarm.min_engine_rpm)[1]
    holds = hold_flags(rec["SpoolCmd"])
    with np.errstate(invalid="ignore"):
        standby = (rec["PP"] < standby_bar).astype(np.int64)
    return {"e": e, "t": rec.t, "holds": holds, "holds at standby": holds & standby}


def _judge(runs: dict[str, dict], held: list[str], which: str, watched: tuple[int, ...]) -> None:
    """H fitted on the ``held`` runs with the ``which`` holds counted, judged on every run."""
    try:
        scale = fit_hold_scale(
            [runs[n]["e"] for n in held],
            [runs[n][which] for n in held],
            WINDOW_N,
            MIN_COUNT,
            SETTLE_N,
            watched,
        )
    except InputFileError as exc:
        print(f"{which}: H cannot be fitted: {exc}")
        return
    hold = HoldModel(WINDOW_N, MIN_COUNT, SETTLE_N, watched, scale)
    h = {n: hold_series(r["e"], r[which], hold) for n, r in runs.items()}
    top = {n: float(np.nanmax(s)) if np.isfinite(s).any() else np.nan for n, s in h.items()}
    h0 = 2 * max(top[n] for n in held)
    print(f"\n{which}: scale PA {scale[0]:.4f}, PB {scale[1]:.4f} (z), h0 {h0:.3g}")
    print("  held-out runs, largest H / h0: " + ", ".join(f"{top[n] / h0:.2f}" for n in held))
    normal = [n for n in runs if n.startswith("normal")]
    worst = max(normal, key=lambda n: np.nan_to_num(top[n]))
    over = sum(top[n] > h0 for n in normal)
    print(f"  normal runs: largest H / h0 {top[worst] / h0:.2f} ({worst}), {over} above 1")
    found = 0
    for n in (n for n in runs if n.startswith("piston")):
        after = runs[n]["t"] >= ONSET_S
        s = h[n][after] / h0
        if not np.isfinite(s).any():
            print(f"  {n}: H never judged after the onset (too few counted holds)")
            continue
        first = np.flatnonzero(s > 1)
        found += bool(first.size)
        when = f", above h0 from {runs[n]['t'][after][first[0]]:.0f} s" if first.size else ""
        print(f"  {n}: largest H / h0 after the onset {np.nanmax(s):.2f}{when}")
    print(f"  piston wear found on {found} of {sum(n.startswith('piston') for n in runs)} runs")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    shipped = resource_path("config", "stick_excavator4.model.npz")
    ap.add_argument("--model", type=Path, default=shipped, help="a stick section model")
    ap.add_argument("--held", default="201-202", help="seeds of held-out normal runs, A-B")
    ap.add_argument("--normal", default="401-412", help="seeds of normal runs, A-B")
    ap.add_argument("--faulty", default="501-508", help="seeds of faulty runs, A-B")
    ap.add_argument("--severity", type=float, default=0.5)
    ap.add_argument("--out", type=Path, required=True, help="folder for the simulated runs")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    cfg = load_config(resource_path("config", "excavator4.yaml"))
    model = load_model(args.model)
    standby_bar = cfg.gating.plausibility.pump.ls_margin_bar + STANDBY_ABOVE_MARGIN_BAR
    runs: dict[str, dict] = {}
    for kind, seeds in (("held", args.held), ("normal", args.normal), ("piston_wear", args.faulty)):
        for seed in _seeds(seeds):
            path = _simulate(args.out, kind, seed, args.severity)
            runs[f"{kind}_{seed}"] = _run(path, cfg, model, standby_bar)
    held = [n for n in runs if n.startswith("held")]
    print(f"{args.model.name}: {len(held)} held-out, standby below {standby_bar:g} bar")
    watched = tuple(model.spec.outputs.index(o) for o in ("PA", "PB"))
    for which in ("holds", "holds at standby"):
        _judge(runs, held, which, watched)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
