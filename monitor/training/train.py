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
from typing import Any

import numpy as np

from monitor.detection.alarm import N_REGIMES, AlarmConfig, Isolator
from monitor.errors import ConfigError, InputFileError
from monitor.io.recording import Recording
from monitor.model.bias import BiasModel, bias_regimes, bias_series, fit_scale
from monitor.model.dgrnn import DGRNN
from monitor.model.endstop import StrokeModel, fit_stroke
from monitor.model.envelope import envelope_from_recordings
from monitor.model.grnn import GRNN
from monitor.model.hold import HOLD_OUTPUTS, HoldModel, counted_holds, fit_hold_scale, hold_series
from monitor.model.lever import (
    LEVER_OUTPUT,
    LeverModel,
    fit_lever_scale,
    lever_directions,
    lever_series,
)
from monitor.model.modelfile import MonitorModel
from monitor.model.residual import window_j
from monitor.model.spec import DGRNNSpec, Normalizer, table
from monitor.model.threshold import MIN_BLOCKS, one_event
from monitor.signals import FAULT_NAMES
from monitor.training.crossfit import cross_fitted_residuals, n_blocks
from monitor.training.settings import TrainConfig

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
    crossfit = not held_out and cfg.folds >= 2 and n_blocks(
        [len(r) for r in recordings], block_n) >= 2 * cfg.folds  # fmt: skip
    if held_out:
        fit_part, val_part = list(recordings), list(held_out)
    elif crossfit:
        fit_part, val_part = list(recordings), list(recordings)
    else:
        fit_part, val_part = split_normal(recordings, cfg.validation_fraction)
        if cfg.folds >= 2:
            say(f"  too short to cross-fit {cfg.folds} folds of {cfg.fold_block_s:g} s blocks "
                f"(needs {2 * cfg.folds * cfg.fold_block_s / 60:g} min): the last "
                f"{cfg.validation_fraction:.0%} held out for the thresholds")  # fmt: skip
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

        say(f"  {lend(dgrnn)} patterns lent by the reference model where this machine's own "
            "data has none")  # fmt: skip
    model = MonitorModel(dgrnn, normalizer, cfg.window_n, cfg.threshold, math.nan, math.nan)
    # Held-out residuals once, unbounded; the bound (if any) is learnt from them and then
    # applied exactly as the detector applies it.
    if crossfit:
        say(f"  thresholds cross-fitted: {cfg.folds} folds of {cfg.fold_block_s:g} s blocks")
        e_val = cross_fitted_residuals(
            model, [normalizer.transform(t) for t in tables], val_part, cfg.folds, block_n,
            normal_residuals, say, lend)  # fmt: skip
    else:
        e_val = [normal_residuals(model, r) for r in val_part]
    if cfg.residual_clip_quantile is not None:
        clip = np.nanquantile(np.abs(np.concatenate(e_val)), cfg.residual_clip_quantile, axis=0)
        model.residual_clip = tuple(float(c) for c in clip)
        say(f"  residual bound |e| <= {', '.join(f'{c:.3g}' for c in clip)} (z, per output)")
        e_val = [np.clip(e, -clip, clip) for e in e_val]
    j_parts = [window_j(e, cfg.window_n) for e in e_val]
    model.j0, model.eps0 = cfg.threshold.eps0(np.concatenate(j_parts), block=cfg.window_n)
    say(
        f"  J0 {model.j0:.4g} ({cfg.threshold.rule} of J on {len(val_part)} "
        f"{'cross-fitted' if crossfit else 'held-out'} part(s)),"
        f" eps0 {model.eps0:.4g}: {cfg.threshold.describe()}"
    )
    own_eps0 = model.eps0
    bias_note = "off (--bias off, or the paper preset)"
    if cfg.with_bias:
        spools = [r["SpoolCmd"] if r.has("SpoolCmd") else None for r in val_part]
        # Short commissioning data cannot support the bias threshold: J alone, said.
        model.bias, bias_note = _optional("bias statistic", "b0", cfg, say,
                                          lambda: fit_bias(e_val, spools, cfg))  # fmt: skip
    lever_note = "off (with the bias statistic, on a model that predicts PP)"
    if model.bias is not None and LEVER_OUTPUT in spec.outputs:
        out = spec.outputs.index(LEVER_OUTPUT)
        model.lever, lever_note = _optional(
            "full-lever statistic L", "l0", cfg, say,
            lambda: fit_lever(e_val, [r["SpoolCmd"] for r in val_part], out, cfg))  # fmt: skip
    hold_note = (
        "off (with the bias statistic, on a model that predicts PA and PB)"
        if cfg.hold else "off (not asked for: --hold on)"
    )
    if cfg.hold and model.bias is not None and all(o in spec.outputs for o in HOLD_OUTPUTS):
        outs = tuple(spec.outputs.index(o) for o in HOLD_OUTPUTS)
        model.hold, hold_note = _optional(
            "hold statistic H", "h0", cfg, say,
            lambda: fit_hold(e_val, [r["SpoolCmd"] for r in val_part],
                             [r["QP"] for r in val_part], outs, cfg,
                             _stroke(recordings, held_out)))  # fmt: skip
    floor_note = None
    if reference is not None:
        floor_note = floor_thresholds(model, reference)
        say(f"  thresholds floored by the reference model: {floor_note}")
    # Said only when the event sets the threshold (not when the reference's floor does).
    event = one_event(j_parts, cfg.window_n) if model.eps0 == own_eps0 else None
    if event is not None:
        rec = val_part[int(event.pop("part"))]
        t_s = float(rec.t[min(int(event.pop("start")), len(rec) - 1)])
        event = {"source": rec.source, "t_s": t_s, **event}
        say(f"  note: J0 rests on one event, {event['source']} at {event['t_s'] / 60:.1f} min "
            f"({event['ratio']:.1f} x any other window's J): the threshold is that much less "
            "sensitive unless such events are this machine's normal work; check what it did "
            "then")  # fmt: skip
    # The operating envelope of every training recording (patterns and held-out part): the
    # detector reports samples beyond it as out_of_range instead of judging them.
    everything = [*recordings, *(held_out or ())]
    model.envelope = envelope_from_recordings(everything, AlarmConfig().min_engine_rpm)
    env = model.envelope
    say("  trained envelope: " + ", ".join(
        f"{s} {a:.4g}..{b:.4g}" for s, a, b in zip(env.signals, env.lo, env.hi, strict=True)
    ))  # fmt: skip
    if cfg.isolation == "sim":
        labels, centroids = simulated_signatures(model, cfg, say)
        model.isolation_labels, model.isolation_centroids = labels, centroids
    validation = (f"cross-fitted, {cfg.folds} folds of {cfg.fold_block_s:g} s blocks"
                  if crossfit else "held out")  # fmt: skip
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
        "bias": bias_note,
        "lever": lever_note,
        "hold": hold_note,
        "threshold_floor": floor_note,
        "threshold_one_event": event,
        # The typical J of normal operation judged out of sample: a log's median J against
        # it tells slow wear from the machine's own normal scatter (the fleet's drift).
        "j_median": float(np.nanmedian(np.concatenate(j_parts))),
        "trained_at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    return model


def check_reference(reference: MonitorModel, spec: DGRNNSpec, window_n: int) -> None:
    """ConfigError naming both when ``reference`` is not a model of this spec and window."""
    if reference.spec == spec and reference.window_n == window_n:
        return

    def what(s: DGRNNSpec, n: int) -> str:
        return (f"{'/'.join(s.outputs)} from {'/'.join(s.variables)}, horizon {s.horizon}, "
                f"J window {n}")  # fmt: skip

    raise ConfigError(
        f"the reference model ({what(reference.spec, reference.window_n)}) does not match the "
        f"model to train ({what(spec, window_n)}): train with the reference's preset, "
        "--horizon and --window"
    )


def floor_thresholds(model: MonitorModel, reference: MonitorModel) -> str:
    """Raise eps0 and b0 to at least the reference model's; what was done, in one line.

    Minutes of commissioning cannot show the tail of hours: on simulated machines the
    largest B of 20 cross-fitted minutes (3.5 to 9) stayed far below what 2 hours of the
    same duty cycle reach (17), so thresholds set on it alone raised false alarms.  B is a
    standard score, so the
    reference's b0, set on hours of held-out data, carries over to another machine of the
    type; and a model fitted on minutes predicts no better than the reference fitted on
    hours, so the reference's eps0 is a lower bound for its J."""
    check_reference(reference, model.spec, model.window_n)
    notes = []
    if reference.eps0 > model.eps0:
        notes.append(f"eps0 {model.eps0:.4g} -> {reference.eps0:.4g}")
        model.eps0 = reference.eps0
    rb, mb = reference.bias, model.bias
    if rb is not None and mb is not None and rb.b0 > mb.b0:
        notes.append(f"b0 {mb.b0:.4g} -> {rb.b0:.4g}")
        model.bias = BiasModel(mb.window_n, mb.min_count, mb.scale, rb.b0)
    return ", ".join(notes) or "own thresholds already above the reference's"


def _optional(label: str, threshold: str, cfg: TrainConfig, say: Progress,
              fit: Callable[[], Any]) -> tuple[Any, str]:  # fmt: skip
    """A statistic beside J fitted by ``fit``, or None when the held-out data cannot support
    it (``InputFileError``), with the model file's note ("on" or "off: why"); said."""
    try:
        stat = fit()
    except InputFileError as exc:
        say(f"  {label} off: {exc}")
        return None, f"off: {exc}"
    say(f"  {label} over {cfg.bias_window_n / 100:g} s, {threshold} "
        f"{getattr(stat, threshold):.4g}: {cfg.threshold.describe()}")  # fmt: skip
    return stat, "on"


def _stroke(recordings: Sequence[Recording], held_out: Sequence[Recording] | None
            ) -> StrokeModel:
    """The boom cylinder's swept volumes from every normal recording given: geometry, not a
    threshold, so the training part counts too (``monitor.model.endstop``)."""
    every = [*recordings, *(held_out or ())]
    return fit_stroke([r["SpoolCmd"] for r in every], [r["QP"] for r in every])


def fit_bias(e_val: list[np.ndarray], spool_val: list[np.ndarray], cfg: TrainConfig) -> BiasModel:
    """The bias statistic's scales and threshold b0 from held-out normal residuals
    (``InputFileError`` when they are too short to support them)."""
    if any(s is None for s in spool_val):
        raise InputFileError("the held-out recordings have no SpoolCmd")
    judged = sum(int(np.isfinite(e).all(axis=1).sum()) for e in e_val)
    if judged < MIN_BLOCKS * cfg.bias_window_n:
        # Its threshold must rest on several of its own windows, not on one or two.
        raise InputFileError(
            f"{judged / 6000:.1f} min of held-out normal data; the bias statistic needs "
            f"{MIN_BLOCKS * cfg.bias_window_n / 6000:g} min ({MIN_BLOCKS} windows): give more "
            "with --held-out"
        )
    regimes = [bias_regimes(s) for s in spool_val]
    bias = BiasModel(cfg.bias_window_n, cfg.bias_min_count, fit_scale(e_val, regimes))
    b_val = np.concatenate([bias_series(e, r, bias) for e, r in zip(e_val, regimes, strict=True)])
    _, b0 = cfg.threshold.eps0(b_val, block=cfg.bias_window_n)
    return BiasModel(bias.window_n, bias.min_count, bias.scale, b0)


def fit_lever(
    e_val: list[np.ndarray], spool_val: list[np.ndarray], output: int, cfg: TrainConfig
) -> LeverModel:
    """The full-lever statistic's per-direction scales and threshold l0 from held-out normal
    residuals (``InputFileError`` when they never hold the lever near full)."""
    directions = [lever_directions(s) for s in spool_val]
    scale = fit_lever_scale(e_val, directions, cfg.bias_window_n, cfg.lever_min_count, output)
    lever = LeverModel(cfg.bias_window_n, cfg.lever_min_count, output, scale)
    series = np.concatenate([lever_series(e, d, lever) for e, d in zip(e_val, directions,
                                                                        strict=True)])  # fmt: skip
    _, l0 = cfg.threshold.eps0(series, block=cfg.bias_window_n)
    return LeverModel(lever.window_n, lever.min_count, output, scale, l0)


def fit_hold(
    e_val: list[np.ndarray], spool_val: list[np.ndarray], qp_val: list[np.ndarray],
    outputs: tuple[int, ...], cfg: TrainConfig, stroke: StrokeModel,
) -> HoldModel:
    """The hold statistic's per-output scales and threshold h0 from held-out normal data:
    residuals, SpoolCmd (%) and QP (L/min), the holds on an end stop (``stroke``'s estimate)
    left out (``InputFileError`` when they never hold the lever long enough)."""
    # Holds on an end stop are left out: the healthy model predicts them badly, and a
    # machine lowered into its stop raised false alarms (``monitor.model.endstop``).
    flags = [counted_holds(s, q, stroke) for s, q in zip(spool_val, qp_val, strict=True)]
    scale = fit_hold_scale(e_val, flags, cfg.bias_window_n, cfg.hold_min_count,
                           cfg.hold_settle_n, outputs)  # fmt: skip
    hold = HoldModel(cfg.bias_window_n, cfg.hold_min_count, cfg.hold_settle_n, outputs, scale,
                     stroke=stroke)  # fmt: skip
    series = np.concatenate([hold_series(e, f, hold) for e, f in zip(e_val, flags, strict=True)])
    _, h0 = cfg.threshold.eps0(series, block=cfg.bias_window_n)
    return HoldModel(hold.window_n, hold.min_count, hold.settle_n, outputs, scale, h0, stroke)


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
