"""What the benchmarks run on: simulated boom cycles, models of a chosen size, a long log.

Everything is seeded and built with the product's own code (simulator, GRNN fit, training,
candump writer), so a fresh clone reproduces the inputs; the slow pieces (the 1-hour log,
the 20,000-pattern model) are kept in a work folder keyed by their parameters.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from monitor.codec.logwrite import write_candump
from monitor.io.recording import Recording
from monitor.model.dgrnn import DGRNN
from monitor.model.grnn import GRNN
from monitor.model.modelfile import Isolation, MonitorModel, load_model, save_model
from monitor.model.residual import window_j
from monitor.model.spec import DGRNNSpec, Normalizer, table
from monitor.sim.cycles import make_cycle
from monitor.sim.faults import Fault
from monitor.sim.machine import load_machine
from monitor.sim.simulate import simulate
from monitor.training.settings import DGRNNSettings, IsolationSettings, TrainConfig
from monitor.training.train import (
    normal_residuals,
    simulated_signatures,
    split_normal,
    train,
)

Progress = Callable[[str], None]

TRAIN_SEEDS = tuple(range(1, 9))  # as config/train_default_model.sh
TEST_SEED = 4242


@dataclass(frozen=True)
class Sizes:
    """The sizes a run uses (full or --quick)."""

    patterns: tuple[int, ...]
    horizons: tuple[int, ...]
    headline_patterns: int  # the size of the headline keys (20,000 in a full run)
    train_s: float  # seconds per training recording
    live_s: float  # seconds of 100 Hz data put on the bus
    live_speed: float  # replay speed on the bus
    log_s: float  # length of the detect log
    reference_s: float  # slice the reference pipeline decodes and predicts
    fault_at_s: float  # onset of the fault in the detect log


FULL = Sizes(
    (2_000, 20_000, 200_000), (1, 10, 50), 20_000, 300.0, 600.0, 1.0, 3600.0, 180.0, 3300.0
)
QUICK = Sizes((300, 2_000), (1, 10), 2_000, 40.0, 10.0, 5.0, 90.0, 10.0, 30.0)


def _key(**params: object) -> str:
    return hashlib.sha256(json.dumps(params, sort_keys=True).encode()).hexdigest()[:12]


def training_runs(duration_s: float) -> list[Recording]:
    machine = load_machine()
    return [simulate(make_cycle("boom", duration_s, s), machine, seed=s) for s in TRAIN_SEEDS]


def paper_grnn(recs: list[Recording], n_patterns: int) -> tuple[DGRNN, Normalizer]:
    """An eq. 11 (``paper``, 8 inputs) model with about ``n_patterns`` patterns, and its
    normaliser.  Up to 20,000 patterns the product's thinning (min-distance, radius bisected
    to the bound) with the kept rows as plain patterns, each counting once, so pyGRNN
    computes the same eq. 4 (it has no cluster counts; the kernel's cost is the same);
    beyond, every row is a pattern (greedy thinning is quadratic in the kept count).  Sigma
    is LOO."""
    spec = DGRNNSpec.preset("paper")
    tables = [table(r, spec.variables) for r in recs]
    norm = Normalizer().fit(np.concatenate(tables), spec.variables)
    zs = [norm.transform(t) for t in tables]
    rows = sum(len(z) for z in zs)
    if n_patterns <= 20_000:  # a small radius, so that the pattern bound binds
        grnn = GRNN(max_patterns=n_patterns, min_distance=1e-3, cluster_weights=False)
    else:
        grnn = GRNN(thinning="stride", stride=1, max_patterns=None, loo_max_queries=200)
    model = DGRNN(spec, grnn)
    if n_patterns > 20_000 and rows > n_patterns:  # keep the first n_patterns rows
        keep, zs_cut = n_patterns + len(zs) * spec.max_lag, []
        for z in zs:
            zs_cut.append(z[: max(0, keep)])
            keep -= len(z)
        zs = [z for z in zs_cut if len(z) > spec.max_lag]
    model.fit(zs)
    return model, norm


def monitor_model(work: Path, n_patterns: int, train_s: float, say: Progress) -> Path:
    """The default-preset monitor model with about ``n_patterns`` patterns (cached file).

    ``monitor train`` thins patterns at a minimum distance of 0.05 (z units), which keeps
    about 7,600 of the default preset's rows however large ``max_patterns`` is.  So the model
    is trained as usual without isolation, its GRNN refitted on the same rows with a radius
    small enough for the pattern bound to bind and the kept rows as plain patterns (count 1,
    so the pyGRNN reference computes the same eq. 4; the kernel's cost is the same as with
    cluster counts), and J0, the residual bound and the fault signatures learnt again for
    that GRNN with training's own steps.
    """
    path = work / f"default_{n_patterns}_{_key(n=n_patterns, s=train_s, v=3)}.model.npz"
    if path.exists():
        load_model(path)  # a stale or corrupt cache file fails here, loudly
        return path
    say(f"training a default-preset model with {n_patterns} patterns (cached in {path})")
    recs = training_runs(train_s)
    cfg = TrainConfig(
        dgrnn=DGRNNSettings(max_patterns=n_patterns),
        isolation=IsolationSettings(method="none", runs=1),
    )
    model = train(recs, cfg, say)
    fit_part, val_part = split_normal(recs, cfg.thresholds.validation_fraction)
    spec = model.spec
    tables = [model.normalizer.transform(table(r, spec.variables)) for r in fit_part]
    grnn = GRNN(
        exclude_neighbours=cfg.dgrnn.exclude_neighbours,
        max_patterns=n_patterns,
        min_distance=1e-3,
        cluster_weights=False,
    )
    model.dgrnn = DGRNN(spec, grnn).fit(tables)
    say(f"  refitted: {grnn.patterns_.shape[0]} patterns, sigma {grnn.sigma_:.4g}")
    model.residual_clip = None
    e_val = [normal_residuals(model, r) for r in val_part]
    q = cfg.thresholds.residual_clip_quantile
    if q is not None:  # as `monitor train` does
        clip = np.nanquantile(np.abs(np.concatenate(e_val)), q, axis=0)
        model.residual_clip = tuple(float(c) for c in clip)
        e_val = [np.clip(e, -clip, clip) for e in e_val]
    j_val = np.concatenate([window_j(e, cfg.statistics.window_n) for e in e_val])
    model.j0, model.eps0 = cfg.thresholds.rule.eps0(j_val)
    labels, centroids = simulated_signatures(model, cfg, say)
    model.isolation = Isolation(labels, centroids, model.isolation.min_similarity)
    model.training = {
        **model.training,
        "max_patterns": n_patterns,
        "isolation": "sim",
        "note": "GRNN refitted by monitor.bench.data with min_distance 1e-3",
    }
    save_model(path, model)
    return path


def test_recording(duration_s: float, fault_at_s: float | None, seed: int = TEST_SEED):
    faults = [] if fault_at_s is None else [Fault("spool_wear", 0.8, fault_at_s)]
    return simulate(make_cycle("boom", duration_s, seed), load_machine(), faults, seed=seed)


def long_log(work: Path, duration_s: float, fault_at_s: float, say: Progress) -> Path:
    """A candump log of ``duration_s`` of boom cycles, a spool-wear fault from
    ``fault_at_s`` (cached file).  Three frames per 10 ms sample (pressures, flow and the
    commands the default preset needs) plus the 1 Hz oil temperature: 1.08 M frames an
    hour, more than the issue's two-frames-per-sample 720,000."""
    path = work / f"boom_{int(duration_s)}s_{_key(d=duration_s, f=fault_at_s, v=1)}.log"
    if path.exists():
        return path
    say(f"simulating and writing a {duration_s:.0f} s candump log (cached in {path})")
    rec = test_recording(duration_s, fault_at_s)
    # Without RodPos (optional in the contract; the model does not use it).
    rec = Recording(rec.t, {k: v for k, v in rec.columns.items() if k != "RodPos"}, rec.source)
    tmp = path.with_suffix(".tmp")
    write_candump(tmp, rec)
    tmp.replace(path)
    return path


def model_summary(model: MonitorModel) -> dict[str, object]:
    g = model.dgrnn.grnn
    return {
        "preset": model.training.get("preset"),
        "patterns": int(g.patterns_.shape[0]),
        "inputs": int(g.patterns_.shape[1]),
        "outputs": int(g.targets_.shape[1]),
        "sigma": float(g.sigma_),
    }
