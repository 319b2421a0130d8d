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
from dataclasses import dataclass

import numpy as np

from monitor.detection.alarm import N_REGIMES, AlarmConfig, Isolator
from monitor.errors import InputFileError
from monitor.io.recording import Recording
from monitor.model.dgrnn import DGRNN
from monitor.model.envelope import envelope_from_recordings
from monitor.model.grnn import GRNN
from monitor.model.modelfile import Isolation, MonitorModel
from monitor.model.residual import J
from monitor.model.spec import DGRNNSpec, Normalizer, table
from monitor.model.statistic import HeldOut
from monitor.model.threshold import one_event
from monitor.signals import FAULT_NAMES, source_signal
from monitor.training.crossfit import cross_fitted_residuals, n_blocks
from monitor.training.settings import ThresholdSettings, TrainConfig
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


@dataclass(frozen=True)
class _Parts:
    """Which recordings give the patterns and which the thresholds, and how (the model
    file's ``validation``)."""

    fit: list[Recording]
    val: list[Recording]
    everything: list[Recording]
    crossfit: bool = False
    validation: str = "held out"


def train(
    recordings: Sequence[Recording],
    cfg: TrainConfig,
    progress: Progress | None = None,
    held_out: Sequence[Recording] | None = None,
    reference: MonitorModel | None = None,
) -> MonitorModel:
    """A model from normal ``recordings``; the thresholds come from ``held_out`` normal
    recordings when given, else from residuals cross-fitted over all of them
    (``monitor.training.crossfit``), or from their last ``validation_fraction`` when
    they are too short for ``folds`` folds (or ``folds`` is 0).  A ``reference``
    model of the same machine type (trained on hours) floors both thresholds: see
    :func:`floor_thresholds`."""
    say = progress or (lambda _msg: None)
    spec = cfg.spec()
    check_inputs(recordings, held_out, spec, cfg, reference)
    parts = choose_parts(recordings, held_out, cfg.thresholds, say)
    tables = [table(r, spec.variables) for r in parts.fit]
    model, lend = fit_model(tables, spec, cfg, reference, say)
    e_val = held_out_residuals(model, tables, parts, cfg.thresholds, lend, say)
    held = HeldOut(e_val, parts.val, spec.outputs, parts.everything, parts.validation)
    notes, support = fit_statistics(model, held, cfg, say)
    own_eps0 = model.eps0
    floor_note = None
    if reference is not None:
        floor_note = floor_thresholds(model, reference)
        say(f"  thresholds floored by the reference model: {floor_note}")
    window_n = cfg.statistics.window_n
    judge = J().use(J.get(model))  # J as the model judges (samples on a stop left out)
    j_parts = [judge.series(e, r) for e, r in zip(e_val, parts.val, strict=True)]
    # Said only when the event sets the threshold (not when the reference's floor does).
    own = model.eps0 == own_eps0
    event = one_event_note(j_parts, parts.val, window_n) if own else None
    # The operating envelope of every training recording (patterns and held-out part): the
    # detector reports samples beyond it as out_of_range instead of judging them.
    model.envelope = envelope_from_recordings(parts.everything, AlarmConfig().min_engine_rpm)
    env = model.envelope
    say(
        "  trained envelope: "
        + ", ".join(
            f"{s} {a:.4g}..{b:.4g}" for s, a, b in zip(env.signals, env.lo, env.hi, strict=True)
        )
    )
    if cfg.isolation.method == "sim":
        labels, centroids = simulated_signatures(model, cfg, say)
        model.isolation = Isolation(labels, centroids, model.isolation.min_similarity)
    model.training = {
        **training_record(parts, spec, cfg),
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


def check_inputs(
    recordings: Sequence[Recording],
    held_out: Sequence[Recording] | None,
    spec: DGRNNSpec,
    cfg: TrainConfig,
    reference: MonitorModel | None,
) -> None:
    """Before the long work: data to train on, a reference of this spec and window, and
    every signal the preset reads in every recording."""
    if not recordings:
        raise InputFileError("no normal recordings to train on")
    if reference is not None:
        check_reference(reference, spec, cfg.statistics.window_n)
    for rec in [*recordings, *(held_out or ())]:
        missing = [source_signal(n) for n in spec.variables if not rec.has(n)]
        if missing:
            raise InputFileError(f"{rec.source}: missing signal(s) {', '.join(missing)}")


def choose_parts(
    recordings: Sequence[Recording],
    held_out: Sequence[Recording] | None,
    thresholds: ThresholdSettings,
    say: Progress,
) -> _Parts:
    """The recordings given apart, else cross-fitted folds when the data is long enough for
    them, else the last share of the data held out."""
    folds, block_s = thresholds.folds, thresholds.fold_block_s
    everything = [*recordings, *(held_out or ())]
    if held_out:
        return _Parts(list(recordings), list(held_out), everything)
    if folds >= 2 and n_blocks([len(r) for r in recordings], thresholds.block_n) >= 2 * folds:
        text = f"cross-fitted, {folds} folds of {block_s:g} s blocks"
        return _Parts(list(recordings), list(recordings), everything, True, text)
    fraction = thresholds.validation_fraction
    if folds >= 2:
        say(
            f"  too short to cross-fit {folds} folds of {block_s:g} s blocks "
            f"(needs {2 * folds * block_s / 60:g} min): the last "
            f"{fraction:.0%} held out for the thresholds"
        )
    fit_part, val_part = split_normal(recordings, fraction)
    return _Parts(fit_part, val_part, everything)


def fit_model(
    tables: list[np.ndarray],
    spec: DGRNNSpec,
    cfg: TrainConfig,
    reference: MonitorModel | None,
    say: Progress,
) -> tuple[MonitorModel, Callable[[DGRNN], int] | None]:
    """The normaliser and the DGRNN on the patterns part, with the reference's patterns lent
    where asked; the model has no thresholds yet.  Also returns the lending step (None:
    none), which every cross-fitted fold repeats."""
    normalizer = Normalizer().fit(np.concatenate(tables), spec.variables)
    started = time.perf_counter()
    ds = cfg.dgrnn
    say(
        f"fitting the {ds.preset} DGRNN on {sum(len(t) for t in tables)} samples "
        f"from {len(tables)} part(s)"
    )
    grnn = GRNN(exclude_neighbours=ds.exclude_neighbours, max_patterns=ds.max_patterns)
    dgrnn = DGRNN(spec, grnn).fit([normalizer.transform(t) for t in tables])
    say(
        f"  {grnn.patterns_.shape[0]} patterns, sigma {grnn.sigma_:.4g} (LOO, +-"
        f"{ds.exclude_neighbours} samples excluded) in {time.perf_counter() - started:.1f} s"
    )
    lend = None
    if reference is not None and ds.lend:
        from monitor.training.fill import lend_patterns

        def lend(d: DGRNN) -> int:
            return lend_patterns(d, normalizer, reference)

        say(
            f"  {lend(dgrnn)} patterns lent by the reference model where this machine's own "
            "data has none"
        )
    window_n = cfg.statistics.window_n
    rule = cfg.thresholds.rule
    return MonitorModel(dgrnn, normalizer, window_n, rule, math.nan, math.nan), lend


def held_out_residuals(
    model: MonitorModel,
    tables: list[np.ndarray],
    parts: _Parts,
    thresholds: ThresholdSettings,
    lend: Callable[[DGRNN], int] | None,
    say: Progress,
) -> list[np.ndarray]:
    """Residuals of the data the thresholds rest on, each part predicted by a model that
    never saw it; bounded per output when asked (the bound is then kept in ``model``)."""
    # Held-out residuals once, unbounded; the bound (if any) is learnt from them and then
    # applied exactly as the detector applies it.
    if parts.crossfit:
        folds, block_s = thresholds.folds, thresholds.fold_block_s
        say(f"  thresholds cross-fitted: {folds} folds of {block_s:g} s blocks")
        normalizer = model.normalizer
        e_val = cross_fitted_residuals(
            model,
            [normalizer.transform(t) for t in tables],
            parts.val,
            folds,
            thresholds.block_n,
            normal_residuals,
            say,
            lend,
        )
    else:
        e_val = [normal_residuals(model, r) for r in parts.val]
    q = thresholds.residual_clip_quantile
    if q is None:
        return e_val
    clip = np.nanquantile(np.abs(np.concatenate(e_val)), q, axis=0)
    model.residual_clip = tuple(float(c) for c in clip)
    say(f"  residual bound |e| <= {', '.join(f'{c:.3g}' for c in clip)} (z, per output)")
    return [np.clip(e, -clip, clip) for e in e_val]


def one_event_note(
    j_parts: list[np.ndarray], val_part: list[Recording], window_n: int
) -> dict[str, object] | None:
    """The model file's note when J0 rests on one event (its source and time), else None;
    ``monitor train`` says it with the support rule's warnings
    (``monitor.training.support.rests_on_one_event``)."""
    found = one_event(j_parts, window_n)
    if found is None:
        return None
    rec = val_part[int(found.pop("part"))]
    t_s = float(rec.t[min(int(found.pop("start")), len(rec) - 1)])
    return {"source": rec.source, "t_s": t_s, **found}


def training_record(parts: _Parts, spec: DGRNNSpec, cfg: TrainConfig) -> dict[str, object]:
    """The model file's record of what the model was trained from and how."""
    everything = parts.everything
    return {
        "sources": [r.source for r in everything],
        "patterns_from": [r.source for r in parts.fit],
        "validation_from": [r.source for r in parts.val],
        "validation": parts.validation,
        "samples": int(sum(len(r) for r in everything)),
        "data_sha256": data_hash([table(r, spec.variables) for r in everything]),
        "preset": cfg.dgrnn.preset,
        "max_patterns": cfg.dgrnn.max_patterns,
        "residual_clip_quantile": cfg.thresholds.residual_clip_quantile,
        "isolation": cfg.isolation.method,
        "threshold": cfg.thresholds.rule.describe(),
    }


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
        f"{len(FAULT_NAMES) * len(ISOLATION_SEVERITIES) * cfg.isolation.runs} simulated runs"
    )
    for k, fault in enumerate(FAULT_NAMES):
        for sev in ISOLATION_SEVERITIES:
            acc = Isolator((), np.zeros((0, N_REGIMES * n_out)), n_out)
            for r in range(cfg.isolation.runs):
                seed = 70_000 + 1000 * k + 100 * r + int(round(sev * 20)) + cfg.isolation.seed
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
