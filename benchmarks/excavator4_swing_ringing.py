"""How much of the house's ringing after a quick swing stop a swing model's one-step
prediction follows: the least-squares gain of predicted on measured pressure steps over the
3 s after the lever is back at centre (1: all of it; the shipped model 0.5-0.75).

    python benchmarks/excavator4_swing_ringing.py [MODEL.npz ...]   # default: the shipped

Each case is 9 s of the whole machine (``simulate_whole``, sensor noise of seed 0): the
swing at AMP % for RUN s let go at the operator's 200 %/s, the boom lowering at BOOM % let
go with it (0: still), oil at OIL degC; the first is normal run 113000000's (seed set 11,
383.2-386.9 s), whose ringing put the swing's B at 4.56 x b0.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from monitor.config.settings import load_config
from monitor.detection.offline import residual_series
from monitor.io.csvio import write_csv
from monitor.io.recording import Recording
from monitor.model.modelfile import load_model
from monitor.offline.recordings import loop_recording
from monitor.resources import resource_path
from monitor.sim.cycles import RATE_LIMIT_PCT_S, rate_limit
from monitor.sim.whole.params import load_whole_machine
from monitor.sim.whole.simulate import simulate_whole

CONFIG = resource_path("config", "excavator4.yaml")
#: (swing lever %, held s, boom lever %, oil degC)
CASES = (
    (86.0, 2.4, -62.0, 49.4),
    (86.0, 2.4, 0.0, 49.4),
    (60.0, 1.5, -40.0, 45.0),
    (100.0, 3.0, -80.0, 55.0),
    (-86.0, 2.4, -62.0, 49.4),
)


def quick_stop(folder: Path, amp: float, run_s: float, boom: float, oil_c: float) -> Recording:
    """The swing's loop recording of one quick stop (the module's docstring)."""
    n = 900
    t = np.arange(n) * 0.01
    on = (t >= 1.0) & (t < 1.0 + run_s)
    zero = np.zeros(n)
    cols = {
        "SpoolCmd": rate_limit(np.where(on, boom, 0.0), RATE_LIMIT_PCT_S),
        "Stick_SpoolCmd": zero,
        "Bucket_SpoolCmd": zero,
        "Swing_SpoolCmd": rate_limit(np.where(on, amp, 0.0), RATE_LIMIT_PCT_S),
        "EngineSpeed": np.full(n, 2200.0),
        "OilTemp": np.full(n, oil_c),
        "DigForce": zero,
        "Payload": zero,
    }
    rec = simulate_whole(Recording(t, cols, source="quick stop"), load_whole_machine(), [], seed=0)
    path = folder / "quick_stop.csv"
    write_csv(path, rec)
    return loop_recording(path, load_config(CONFIG), "swing")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("models", nargs="*", type=Path, help="swing model files (default: shipped)")
    args = ap.parse_args()
    cfg = load_config(CONFIG)
    shipped = next(lc.model for lc in cfg.monitored_loops if lc.name == "swing")
    paths = args.models or [shipped]
    models = {p: load_model(p) for p in paths}
    with tempfile.TemporaryDirectory() as tmp:
        for amp, run_s, boom, oil_c in CASES:
            rec = quick_stop(Path(tmp), amp, run_s, boom, oil_c)
            back = int(round((1.0 + run_s + abs(amp) / RATE_LIMIT_PCT_S) / 0.01))
            ring, before = slice(back, back + 300), slice(back - 1, back + 299)
            cells = []
            for model in models.values():
                y_hat, _ = residual_series(model, rec, np.zeros(len(rec.t), dtype=bool))
                outs = list(model.spec.outputs)
                for name in ("PA", "PB"):
                    y = np.asarray(rec[name])
                    meas = y[ring] - y[before]
                    pred = y_hat[ring, outs.index(name)] - y[before]
                    cells.append(f"{np.dot(pred, meas) / np.dot(meas, meas):.2f}")
            print(
                f"| {amp:+.0f} % {run_s:g} s, boom {boom:+.0f} %, {oil_c:g} degC | "
                + " | ".join(cells)
                + " |"
            )
    print("(gain PA, PB per model: " + ", ".join(str(p) for p in paths) + ")")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
