"""``monitor train``: normal recordings -> a verified model file.

The thresholds are set on residuals of data the GRNN never saw: recordings given apart
(``--held-out``), or, by default, residuals cross-fitted over all the normal data, each block
predicted by a model fitted on the others (``crossfit.py``); data too short for that is split
in two, the patterns (and the z-score statistics, F0) from the first part, J0 from the rest.
Fault isolation learns one residual signature per fault from the simulator (the product's
own physics model), driven through the freshly trained DGRNN.
"""

from __future__ import annotations

import hashlib
import math
import time
from collections.abc import Callable, Sequence

import numpy as np

from monitor.detection.alarm import N_REGIMES, AlarmConfig, Isolator
from monitor.errors import InputFileError
from monitor.io.recording import Recording
from monitor.model.dgrnn import DGRNN
from monitor.model.envelope import envelope_from_recordings
from monitor.model.grnn import GRNN
from monitor.model.modelfile import Isolation, MonitorModel
from monitor.model.residual import window_j
from monitor.model.spec import Normalizer, table
from monitor.model.statistic import HeldOut
from monitor.model.threshold import one_event
from monitor.signals import FAULT_NAMES
from monitor.training.crossfit import cross_fitted_residuals, n_blocks
from monitor.training.settings import TrainConfig
from monitor.training.statistics import check_reference, fit_statistics, floor_thresholds

Progress = Callable[[str], None]


def split_normal(
    recordings: Sequence[Recording], fraction: float
) -> tuple[list[Recording], list[Recording]]:
    """Patterns part and validation part: whole recordings when there are several."""
    recs = list(recordings)
    if len(recs) >= 2:
        n_val = max(1, math.ceil(fraction * len(recs)))
        return recs[:-n_val], recs[-n_val:]
    rec = recs[0]
    cut = int(round(len(rec) * (1 - fraction)))
    head = Recording(rec.t[:cut], {k: v[:cut] for k, v in rec.columns.items()}, rec.source)
    tail = Recording(rec.t[cut:], {k: v[cut:] for k, v in rec.columns.items()}, rec.source)
    return [head], [tail]


def data_hash(arrays: Sequence[np.ndarray]) -> str:
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    return h.hexdigest()


def normal_residuals(model: MonitorModel, rec: Recording) -> np.ndarray:
    """Residuals e over a normal recording, gated exactly as the detector gates them."""
    from monitor.detection.offline import gated_residuals

    return gated_residuals(model, rec, AlarmConfig().min_engine_rpm)[1]


def train(
    recordings: Sequence[Recording],
    cfg: TrainConfig,
    progress: Progress | None = None,
    held_out: Sequence[Recording] | None = None,
    reference: MonitorModel | None = None,
) -> MonitorModel:
    """A model from normal ``recordings``; the thresholds come from ``held_out`` normal
    recordings when given, else from residuals cross-fitted over all of them
    (``monitor.training.crossfit``), or from their last ``cfg.validation_fraction`` when
    they are too short for ``cfg.folds`` folds (or ``cfg.folds`` is 0).  A ``reference``
    model of the same machine type (trained on hours) floors both thresholds: see
    :func:`floor_thresholds`."""
    say = progress or (lambda _msg: None)
    if not recordings:
        raise InputFileError("no normal recordings to train on")
    spec = cfg.spec()
    if reference is not None:  # before the long work
        check_reference(reference, spec, cfg.window_n)
    for rec in [*recordings, *(held_out or ())]:
        missing = [n for n in spec.variables if not rec.has(n)]
        if missing:
            raise InputFileError(f"{rec.source}: missing signal(s) {', '.join(missing)}")
    block_n = int(round(cfg.fold_block_s * 100))
    crossfit = (
        not held_out
        and cfg.folds >= 2
        and n_blocks([len(r) for r in recordings], block_n) >= 2 * cfg.folds
    )
    if held_out:
        fit_part, val_part = list(recordings), list(held_out)
    elif crossfit:
        fit_part, val_part = list(recordings), list(recordings)
    else:
        fit_part, val_part = split_normal(recordings, cfg.validation_fraction)
        if cfg.folds >= 2:
            say(
                f"  too short to cross-fit {cfg.folds} folds of {cfg.fold_block_s:g} s blocks "
                f"(needs {2 * cfg.folds * cfg.fold_block_s / 60:g} min): the last "
                f"{cfg.validation_fraction:.0%} held out for the thresholds"
            )
    tables = [table(r, spec.variables) for r in fit_part]
    normalizer = Normalizer().fit(np.concatenate(tables), spec.variables)
    started = time.perf_counter()
    say(
        f"fitting the {cfg.preset} DGRNN on {sum(len(t) for t in tables)} samples "
        f"from {len(fit_part)} part(s)"
    )
    grnn = GRNN(exclude_neighbours=cfg.exclude_neighbours, max_patterns=cfg.max_patterns)
    dgrnn = DGRNN(spec, grnn).fit([normalizer.transform(t) for t in tables])
    say(
        f"  {grnn.patterns_.shape[0]} patterns, sigma {grnn.sigma_:.4g} (LOO, +-"
        f"{cfg.exclude_neighbours} samples excluded) in {time.perf_counter() - started:.1f} s"
    )
    lend = None
    if reference is not None and cfg.lend:
        from monitor.training.fill import lend_patterns

        def lend(d: DGRNN) -> int:
            return lend_patterns(d, normalizer, reference)

        say(
            f"  {lend(dgrnn)} patterns lent by the reference model where this machine's own "
            "data has none"
        )
    model = MonitorModel(dgrnn, normalizer, cfg.window_n, cfg.threshold, math.nan, math.nan)
    # Held-out residuals once, unbounded; the bound (if any) is learnt from them and then
    # applied exactly as the detector applies it.
    if crossfit:
        say(f"  thresholds cross-fitted: {cfg.folds} folds of {cfg.fold_block_s:g} s blocks")
        e_val = cross_fitted_residuals(
            model,
            [normalizer.transform(t) for t in tables],
            val_part,
            cfg.folds,
            block_n,
            normal_residuals,
            say,
            lend,
        )
    else:
        e_val = [normal_residuals(model, r) for r in val_part]
    if cfg.residual_clip_quantile is not None:
        clip = np.nanquantile(np.abs(np.concatenate(e_val)), cfg.residual_clip_quantile, axis=0)
        model.residual_clip = tuple(float(c) for c in clip)
        say(f"  residual bound |e| <= {', '.join(f'{c:.3g}' for c in clip)} (z, per output)")
        e_val = [np.clip(e, -clip, clip) for e in e_val]
    validation = (
        f"cross-fitted, {cfg.folds} folds of {cfg.fold_block_s:g} s blocks"
        if crossfit
        else "held out"
    )
    everything = [*recordings, *(held_out or ())]
    held = HeldOut(e_val, val_part, spec.outputs, everything, validation)
    notes, support = fit_statistics(model, held, cfg, say)
    own_eps0 = model.eps0
    floor_note = None
    if reference is not None:
        floor_note = floor_thresholds(model, reference)
        say(f"  thresholds floored by the reference model: {floor_note}")
    # Said only when the event sets the threshold (not when the reference's floor does).
    j_parts = [window_j(e, cfg.window_n) for e in e_val]
    found = one_event(j_parts, cfg.window_n) if model.eps0 == own_eps0 else None
    event: dict[str, object] | None = None  # the model file's note: the event's source and time
    if found is not None:
        rec = val_part[int(found.pop("part"))]
        t_s = float(rec.t[min(int(found.pop("start")), len(rec) - 1)])
        event = {"source": rec.source, "t_s": t_s, **found}
        say(
            f"  note: J0 rests on one event, {rec.source} at {t_s / 60:.1f} min "
            f"({found['ratio']:.1f} x any other window's J): the threshold is that much less "
            "sensitive unless such events are this machine's normal work; check what it did "
            "then"
        )
    # The operating envelope of every training recording (patterns and held-out part): the
    # detector reports samples beyond it as out_of_range instead of judging them.
    model.envelope = envelope_from_recordings(everything, AlarmConfig().min_engine_rpm)
    env = model.envelope
    say(
        "  trained envelope: "
        + ", ".join(
            f"{s} {a:.4g}..{b:.4g}" for s, a, b in zip(env.signals, env.lo, env.hi, strict=True)
        )
    )
    if cfg.isolation == "sim":
        labels, centroids = simulated_signatures(model, cfg, say)
        model.isolation = Isolation(labels, centroids, model.isolation.min_similarity)
    model.training = {
        "sources": [r.source for r in everything],
        "patterns_from": [r.source for r in fit_part],
        "validation_from": [r.source for r in val_part],
        "validation": validation,
        "samples": int(sum(len(r) for r in everything)),
        "data_sha256": data_hash([table(r, spec.variables) for r in everything]),
        "preset": cfg.preset,
        "max_patterns": cfg.max_patterns,
        "residual_clip_quantile": cfg.residual_clip_quantile,
        "isolation": cfg.isolation,
        "threshold": cfg.threshold.describe(),
        **notes,  # each statistic: "on", or "off..." and why
        "support": support,
        "threshold_floor": floor_note,
        "threshold_one_event": event,
        # The typical J of normal operation judged out of sample: a log's median J against
        # it tells slow wear from the machine's own normal scatter (the fleet's drift).
        "j_median": float(np.nanmedian(np.concatenate(j_parts))),
        "trained_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    return model


#: Severities the fault signatures are learnt at: one signature per fault and severity, since
#: a fault's residual pattern changes with its size (slight spool wear leaks at hold only).
ISOLATION_SEVERITIES = (0.15, 0.3, 0.5, 1.0)


def simulated_signatures(
    model: MonitorModel, cfg: TrainConfig, say: Progress
) -> tuple[tuple[str, ...], np.ndarray]:
    """Unit-length mean-residual signatures, one per fault and severity (the label repeats),
    from simulated faulty boom cycles; isolation names the nearest."""
    from monitor.detection.alarm import regimes_of
    from monitor.detection.offline import residual_series
    from monitor.sim.cycles import make_cycle
    from monitor.sim.faults import Fault
    from monitor.sim.machine import load_machine
    from monitor.sim.simulate import simulate

    machine = load_machine()
    n_out = len(model.spec.outputs)
    labels, centroids = [], []
    say(
        f"  learning fault signatures from "
        f"{len(FAULT_NAMES) * len(ISOLATION_SEVERITIES) * cfg.isolation_runs} simulated runs"
    )
    for k, fault in enumerate(FAULT_NAMES):
        for sev in ISOLATION_SEVERITIES:
            acc = Isolator((), np.zeros((0, N_REGIMES * n_out)), n_out)
            for r in range(cfg.isolation_runs):
                seed = 70_000 + 1000 * k + 100 * r + int(round(sev * 20)) + cfg.seed
                rec = simulate(
                    make_cycle("boom", 90.0, seed),
                    machine,
                    faults=[Fault(fault, sev, 20.0)],
                    seed=seed,
                )
                _, e = residual_series(model, rec, np.zeros(len(rec), dtype=bool))
                acc.add_many(e[2000:], regimes_of(rec["SpoolCmd"][2000:]))
            sig = np.nan_to_num(acc.signature())
            norm = np.linalg.norm(sig)
            labels.append(fault)
            centroids.append(sig / norm if norm > 0 else sig)
    return tuple(labels), np.array(centroids)
