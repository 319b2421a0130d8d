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
(no transient) and the sections draw over 2 L/min: the pump rule's own counting
(``monitor.detection.pump``), which each run is also judged by with the shipped pump model
(``config/pump_excavator4.pump.json``, ``monitor detect --pump``).  Runs are ``monitor
simulate --machine excavator4`` mixed work of 600 s (``benchmarks/excavator4_loops.py``'s
names, so a folder serves both), the fault ``pump.pump_wear`` from 120 s.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks.excavator4_loops import ONSET_S, _seeds, _simulate
from monitor.config.pump import load_pump, pump_columns
from monitor.config.settings import load_config
from monitor.detection.pump import counted_samples, judge_rows
from monitor.model.pumplaw import Counting, MarginLaw, PumpModel
from monitor.offline.recordings import machine_rows
from monitor.resources import resource_path

CONFIG = resource_path("config", "excavator4.yaml")
#: Independent 0.5 s blocks for the standard error (the residual is correlated within one).
BLOCK = 50


def margin_samples(path: Path, after_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(total section flow L/min, PP bar, margin deficit bar) at the samples the pump rule
    counts (``monitor.detection.pump``: its own choice, so the benchmark and the rule agree)."""
    cfg = load_config(CONFIG)
    columns, rows, _ = machine_rows(path, cfg)
    rows = rows[rows[:, 0] - rows[0, 0] > after_s]
    margin = cfg.gating.plausibility.pump.ls_margin_bar
    blank = PumpModel(MarginLaw(0.0, 0.0, 0.0), Counting(margin), None)
    s = counted_samples(blank, pump_columns(cfg, columns), rows)
    return s[:, 0], s[:, 1], s[:, 2]


def shipped_verdict(path: Path) -> str:
    """The shipped pump model's verdict on the run (``monitor detect --pump``)."""
    cfg = load_config(CONFIG)
    model = load_pump(cfg)
    if model is None:
        return "no pump model"
    columns, rows, _ = machine_rows(path, cfg)
    s = judge_rows(model, pump_columns(cfg, columns), rows).summary
    alarm = f" from {s['first_alarm_t']:.0f} s" if s["alarm"] else ""
    return f"shipped rule {s['verdict']}{alarm} (peak {s['max_margin_residual_bar']} bar)"


def tick_cost(path: Path, n_rows: int = 30_000) -> str:
    """CPU per row of the pump rule and of the boom loop's tick, side by side in one pass
    over the run's rows (``time.thread_time_ns``): what the rule adds to the daemon's row."""
    from monitor.codec.frames import FrameCodec
    from monitor.config.layout import row_layout
    from monitor.detection.pump import PumpRule
    from monitor.detection.ticker import Ticker
    from monitor.model.modelfile import load_model

    cfg = load_config(CONFIG)
    columns, rows, _ = machine_rows(path, cfg)
    _, views = row_layout(cfg, FrameCodec.from_dbc(cfg.dbc))
    model = load_pump(cfg)
    assert model is not None
    rule = PumpRule(model, pump_columns(cfg, columns))
    loop = Ticker(
        load_model(cfg.loops[0].model),
        cfg.alarm,
        cfg.horizon,
        columns=views[0],
        gating=cfg.gating,
    )
    pump_ns, loop_ns = [], []
    for row in rows[:n_rows]:
        c0 = time.thread_time_ns()
        rule.tick(row.tolist())
        c1 = time.thread_time_ns()
        loop.tick(row)
        pump_ns.append(c1 - c0)
        loop_ns.append(time.thread_time_ns() - c1)
    p, q = np.array(pump_ns) / 1e3, np.array(loop_ns) / 1e3
    return (
        f"CPU per row over {len(p)} rows: pump rule median {np.median(p):.1f} us, p99 "
        f"{np.percentile(p, 99):.1f} us; the boom loop's tick median {np.median(q):.1f} us, "
        f"p99 {np.percentile(q, 99):.1f} us; ratio of medians {np.median(p) / np.median(q):.3f}"
    )


def _design(flow: np.ndarray, pp: np.ndarray) -> np.ndarray:
    return np.column_stack([flow, pp, np.ones_like(flow)])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fit", default="101-104", help="seeds of normal runs to fit on, A-B")
    ap.add_argument("--normal", default="401-412", help="seeds of normal runs judged, A-B")
    ap.add_argument("--faulty", default="501-504", help="seeds of worn-pump runs, A-B")
    ap.add_argument("--severity", type=float, default=0.5)
    ap.add_argument("--out", type=Path, required=True, help="folder for the simulated runs")
    ap.add_argument(
        "--tick-cost", action="store_true", help="also time the rule per row (first faulty run)"
    )
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
            f"{r.mean():+.3f} bar (se {se:.3f}); {shipped_verdict(path)}",
            flush=True,
        )
    if args.tick_cost:
        path = _simulate(args.out, _seeds(args.faulty)[0], "pump.pump_wear", args.severity)
        print(tick_cost(path), f"(load average {os.getloadavg()[0]:.1f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
