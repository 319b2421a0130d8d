"""Can the whole machine's shared pump be judged on its own?  The load-sensing margin against
the sections' total flow, on simulated normal operation and on a worn pump.

    python -m benchmarks.excavator4_pump --fit 101-104 --normal 401-424 --faulty 501-504 \
        --out runs/

Why: a worn pump leaks, and its LS regulator makes up the leak with displacement, so no
section sees less flow until the pump saturates (rare in mixed work) and every section's model
(PP an input) stays quiet.  What the extra displacement costs is margin: the regulator holds
PP = PLS + margin - band x displacement, displacement = (sum of the sections' flows + the
pump's leakage) / full flow, so the margin's deficit PLS + margin - PP grows by
band x leakage / full flow.  This script fits deficit = a x sum(QP) + b x PP + c on the
``--fit`` normal runs (physics: a = band / full flow = 5 / 39.6 = 0.126 bar per L/min, b =
band x the healthy leakage / full flow = 5 x 0.010 / 39.6 = 0.0013), then prints each run's
mean residual after the fault's onset (bar) with its standard error.  PLS is read as the
highest feeding port (PA raising, PB lowering) of the sections whose spool is open beyond
5 %; samples count where some section is open, every command has been steady for 0.5 s
(no transient) and the sections draw over 2 L/min.  Runs are ``monitor simulate --machine
excavator4`` mixed work of 600 s (``benchmarks/excavator4_loops.py``'s names, so a folder
serves both), the fault ``pump.pump_wear`` from 120 s.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from benchmarks.excavator4_loops import ONSET_S, _seeds, _simulate
from monitor.io.csvio import read_csv

PREFIXES = ("", "Stick_", "Bucket_", "Swing_")
MARGIN_BAR = 20.0  # config/excavator4.yaml's plausibility.ls_margin_bar
OPEN_PCT = 5.0
STEADY_SAMPLES = 50  # 0.5 s at 100 Hz
MIN_FLOW_LPM = 2.0
#: Independent 0.5 s blocks for the standard error (the residual is correlated within one).
BLOCK = 50


def margin_samples(path: Path, after_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(total section flow L/min, PP bar, margin deficit bar) at the counted samples."""
    rec = read_csv(path)
    flow = sum(rec[p + "QP"] for p in PREFIXES)
    pls = np.zeros(len(rec))
    n_open = np.zeros(len(rec))
    steady = np.ones(len(rec), dtype=bool)
    idx = np.arange(len(rec))
    for p in PREFIXES:
        s = rec[p + "SpoolCmd"]
        port = np.where(s > OPEN_PCT, rec[p + "PA"], np.where(s < -OPEN_PCT, rec[p + "PB"], 0.0))
        pls = np.maximum(pls, port)
        n_open += np.abs(s) > OPEN_PCT
        changed = np.r_[True, np.abs(np.diff(s)) > 0.5]
        last = np.maximum.accumulate(np.where(changed, idx, 0))
        steady &= idx - last > STEADY_SAMPLES
    deficit = pls + MARGIN_BAR - rec["PP"]
    keep = (n_open > 0) & steady & (rec.t - rec.t[0] > after_s) & (flow > MIN_FLOW_LPM)
    return flow[keep], rec["PP"][keep], deficit[keep]


def _design(flow: np.ndarray, pp: np.ndarray) -> np.ndarray:
    return np.column_stack([flow, pp, np.ones_like(flow)])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fit", default="101-104", help="seeds of normal runs to fit on, A-B")
    ap.add_argument("--normal", default="401-412", help="seeds of normal runs judged, A-B")
    ap.add_argument("--faulty", default="501-504", help="seeds of worn-pump runs, A-B")
    ap.add_argument("--severity", type=float, default=0.5)
    ap.add_argument("--out", type=Path, required=True, help="folder for the simulated runs")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    parts = [margin_samples(_simulate(args.out, s, None, 0.0), 0.0) for s in _seeds(args.fit)]
    a = np.vstack([_design(f, p) for f, p, _ in parts])
    coef, *_ = np.linalg.lstsq(a, np.concatenate([d for _, _, d in parts]), rcond=None)
    print(
        f"fitted on {len(parts)} normal runs: deficit = {coef[0]:.4f} x sum(QP) "
        f"+ {coef[1]:.5f} x PP + {coef[2]:.3f} bar (physics: 0.1263, 0.00126, 0)"
    )
    runs = [("normal", s, None) for s in _seeds(args.normal)]
    runs += [("pump_wear", s, "pump.pump_wear") for s in _seeds(args.faulty)]
    for kind, seed, fault in runs:
        path = _simulate(args.out, seed, fault, args.severity)
        flow, pp, deficit = margin_samples(path, ONSET_S)
        r = deficit - _design(flow, pp) @ coef
        n_blocks = max(len(r) // BLOCK, 1)
        se = float(np.std(r) / np.sqrt(n_blocks))
        print(
            f"{kind} seed {seed}: {len(r) / 100:.0f} s counted, mean residual "
            f"{r.mean():+.3f} bar (se {se:.3f})",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
