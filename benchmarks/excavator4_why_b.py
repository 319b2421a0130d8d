"""Why a loop's bias statistic B rises on one run: its peak taken apart by spool regime and
output, and the training patterns the model's kernel leant on where the residual is largest.

    python benchmarks/excavator4_why_b.py runs/normal_406.csv --loop stick \
        --fit fit_101.csv fit_102.csv ...   # the model's training runs, in its order

B (``monitor.model.bias``) at a sample is the mean over the spool regimes counted in its
60 s window of (1/outputs) sum z^2, z the regime's mean residual in standard scores.  The
script prints each regime's z per output at B's peak, then, for the samples of the largest
regime's window with the largest residuals, the one-step prediction (measured lags) and the
patterns carrying most of eq. 4's weight: which training recording and second each pattern's
seed row came from (``--fit``: the recordings the model was trained on, in the order of its
``patterns_from``; without it, the pattern's row index only), its members and its target.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from monitor.config.settings import load_config
from monitor.detection.offline import detect
from monitor.model.bias import REGIME_NAMES, bias_regimes
from monitor.model.dgrnn import build_training_pairs
from monitor.model.modelfile import MonitorModel, load_model
from monitor.offline.recordings import loop_recordings
from monitor.resources import resource_path

SAMPLE_S = 0.01


def regime_table(model: MonitorModel, e: np.ndarray, regimes: np.ndarray, peak: int) -> int:
    """Print each regime's z per output over the window ending at ``peak``; return the
    regime contributing most."""
    bias = model.bias
    a = max(0, peak - bias.window_n + 1)
    ew, rw = e[a : peak + 1], regimes[a : peak + 1]
    ok = np.isfinite(ew).all(axis=1)
    top, top_c = 0, -1.0
    outs = model.spec.outputs
    for r, name in enumerate(REGIME_NAMES):
        sel = ok & (rw == r)
        k = int(sel.sum())
        if k == 0:
            continue
        z = ew[sel].mean(axis=0) * np.sqrt(k) / bias.scale[r]
        contrib = float(np.sum(z**2) / len(z))
        counted = k >= bias.min_count
        zs = ", ".join(f"{o} {v:+.2f}" for o, v in zip(outs, z, strict=True))
        print(
            f"  {name:12s} {k:5d} samples  z: {zs}  (1/n) sum z^2 {contrib:6.1f}"
            + ("" if counted else "  (not counted)")
        )
        if counted and contrib > top_c:
            top, top_c = r, contrib
    return top


def pattern_sources(model: MonitorModel, fit: list[Path], cfg, loop: str) -> list[tuple]:
    """(name, first row index, rows) of each training recording, as ``DGRNN.fit`` numbers
    them (recordings apart by ``exclude_neighbours`` + 1 rows)."""
    gap = int(model.dgrnn.grnn.exclude_neighbours_) + 1
    out, offset = [], 0
    for path in fit:
        n = len(loop_recordings(path, cfg, [loop])[loop])
        out.append((path.name, offset, n))
        offset += n + gap
    return out


def where(index: int, sources: list[tuple]) -> str:
    for name, start, n in sources:
        if start <= index < start + n:
            return f"{name} t={(index - start) * SAMPLE_S:.2f} s"
    return f"row {index}"


def kernel_weights(model: MonitorModel, rec, samples: np.ndarray, sources: list[tuple]) -> None:
    """Eq. 4's weights at each sample (one-step, measured lags), the heaviest patterns."""
    spec, g = model.spec, model.dgrnn.grnn
    names = list(spec.variables)
    z = model.normalizer.transform({v: rec[v] for v in names}, names)
    x, y, t = build_training_pairs(spec, z)
    sd = model.normalizer.std_[[list(model.normalizer.names_).index(o) for o in spec.outputs]]
    unit = np.where(spec.delta_mask().astype(bool), "/step", "")
    sigma = g.sigma_
    for i in samples:
        k = int(np.searchsorted(t, i))
        if k >= len(t) or t[k] != i:
            continue
        d2 = np.sum((g.patterns_ - x[k]) ** 2, axis=1)
        w = g.counts_ * np.exp(-d2 / (2.0 * sigma * sigma))
        support = float(w.sum())  # members within about sigma: the kernel's density here
        w = w / support
        pred = (w @ g.targets_) * sd
        obs = y[k] * sd
        print(
            f"  t={rec.t[i]:.2f} s: predicted "
            + ", ".join(
                f"{o} {p:+.2f}{u}" for o, p, u in zip(spec.outputs, pred, unit, strict=True)
            )
            + "; measured "
            + ", ".join(f"{o} {v:+.2f}" for o, v in zip(spec.outputs, obs, strict=True))
            + f" (physical units); kernel support {support:.2f} members"
        )
        for j in np.argsort(-w)[:3]:
            tgt = ", ".join(
                f"{o} {v:+.2f}" for o, v in zip(spec.outputs, g.targets_[j] * sd, strict=True)
            )
            print(
                f"      weight {w[j]:.3f}  {int(g.counts_[j]):4d} members  "
                f"{where(int(g.pattern_index_[j]), sources)}  target {tgt}"
            )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path, help="a whole-machine recording (CSV or candump)")
    ap.add_argument("--loop", default="stick")
    ap.add_argument("--config", type=Path, default=resource_path("config", "excavator4.yaml"))
    ap.add_argument("--fit", type=Path, nargs="*", default=[], help="the model's training runs")
    ap.add_argument("--samples", type=int, default=4, help="largest residuals to explain")
    args = ap.parse_args()
    cfg = load_config(args.config)
    model = load_model(next(lc.model for lc in cfg.monitored_loops if lc.name == args.loop))
    if model.bias is None:
        raise SystemExit(f"the {args.loop} model has no bias statistic")
    rec = loop_recordings(args.run, cfg, [args.loop])[args.loop]
    res = detect(model, rec, cfg.alarm, cfg.horizon, gating=cfg.gating)
    b = res.series["B"]
    peak = int(np.nanargmax(b))
    print(
        f"{args.run.name} {args.loop}: B {b[peak]:.1f} at {rec.t[peak]:.2f} s "
        f"against b0 {model.bias.b0:.1f}; first alarm {res.summary.get('first_alarm_t')}"
    )
    regimes = bias_regimes(rec["SpoolCmd"])
    top = regime_table(model, res.residual, regimes, peak)
    a = max(0, peak - model.bias.window_n + 1)
    idx = a + np.flatnonzero(regimes[a : peak + 1] == top)
    size = np.nansum(np.abs(res.residual[idx]), axis=1)
    print(
        f"{REGIME_NAMES[top]}: {size.size} samples, the {args.samples} with the largest residuals:"
    )
    chosen = np.sort(idx[np.argsort(-size)[: args.samples]])
    sources = pattern_sources(model, args.fit, cfg, args.loop)
    kernel_weights(model, rec, chosen, sources)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
