"""One loop of a log, trained or judged: the one implementation of `monitor train --loop`'s
model inputs and card and of `monitor detect [--loop]`'s judging, shared by those commands
and by `monitor fleet run` (which trains and judges every loop of a whole machine).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from monitor.config.layout import check_loop_model
from monitor.config.settings import LoopConfig, MonitorConfig
from monitor.errors import ConfigError
from monitor.offline.recordings import read_loop

if TYPE_CHECKING:
    from monitor.detection.offline import Detection
    from monitor.io.recording import Recording
    from monitor.model.machinecard import ModelCard
    from monitor.model.modelfile import MonitorModel


def loop_config(cfg: MonitorConfig, name: str | None) -> LoopConfig:
    """Loop ``name`` of ``cfg`` (None: its first, the recording read as one loop)."""
    for lc in cfg.monitored_loops:
        if name in (None, lc.name):
            return lc
    names = ", ".join(lc.name for lc in cfg.monitored_loops)
    raise ConfigError(f"{cfg.source}: no loop {name!r} (loops: {names})")


def section_inputs(
    cfg: MonitorConfig, loop: str | None, preset: str | None = None
) -> tuple[str, tuple[str, ...]]:
    """(preset, the neighbours' demand columns it reads) of a model of ``loop``: ``section``
    for a loop of a load-sensing machine unless ``preset`` says otherwise; a section model
    of a loop reads every other loop's spool command (``monitor.signals.neighbour``)."""
    from monitor.signals import neighbour

    ls = cfg.gating.plausibility.pump.load_sensing
    preset = preset or ("section" if ls and loop else "default")
    if preset != "section" or loop is None:
        return preset, ()
    others = [lc.name for lc in cfg.monitored_loops if lc.name != loop]
    return preset, tuple(neighbour("SpoolCmd", name) for name in others)


def loop_card(
    cfg: MonitorConfig, loop: str | None, recordings: list[Recording], machine_id: str | None
) -> ModelCard:
    """The card `monitor train [--loop]` writes: the loop trained (``loop``, or the
    config's first) and its configured machine, commissioned on ``machine_id``; the
    recordings must be ones that machine can produce (checked before training)."""
    import numpy as np

    from monitor.model.machinecard import card_for, check_seen

    lc = loop_config(cfg, loop)
    where = f"{cfg.source} (machine {lc.machine_source})"
    if lc.machine is not None:
        for rec in recordings:
            seen = {
                s: float(np.nanmax(rec[s], initial=0.0))
                for s in ("PP", "PA", "PB", "QP")
                if rec.has(s)
            }
            check_seen(seen, lc.machine, f"{rec.source}: shows", where)
    source = None if lc.machine_source is None else str(lc.machine_source)
    return card_for(lc.name, lc.machine, source, machine_id)


@dataclass
class Judged:
    """A recording judged as `monitor detect` judges it: what was read, the detection, and
    the reason hydraulic alarms were withheld (a model not commissioned on this machine)."""

    rec: Recording
    det: Detection
    reference: str | None


def check_whole_recording(
    loop: str | None, model: MonitorModel, cfg: MonitorConfig, model_path: str | Path
) -> None:
    """Without a loop the recording is read as one loop's: a model that reads the other
    loops' commands (``SpoolCmd@LOOP``) needs one."""
    from monitor.signals import is_neighbour

    if loop is None and any(is_neighbour(v) for v in model.spec.variables):
        names = ", ".join(lc.name for lc in cfg.monitored_loops)
        raise ConfigError(
            f"{model_path}: a model of one loop of several (it reads the other loops' "
            f"commands): give --loop NAME ({names})"
        )


def check_model(
    model: MonitorModel, cfg: MonitorConfig, loop: str | None, model_path: str | Path
) -> None:
    """Refuse ``model`` for ``loop`` (None: the recording as one loop) before any log is
    read: trained on another loop or machine, or a section model read without its loop."""
    if loop is not None:
        check_loop_model(model, loop_config(cfg, loop), cfg, model_path)
    check_whole_recording(loop, model, cfg, model_path)


def judge_recording(
    model: MonitorModel,
    path: str | Path,
    cfg: MonitorConfig,
    loop: str | None,
    machine_id: str | None,
    horizon: int | None = None,
) -> Judged:
    """`monitor detect PATH [--loop LOOP]` (the model checked first, :func:`check_model`):
    loop ``loop`` of the log (None: the log as one loop) read and judged; a model not
    commissioned on ``machine_id`` withholds its hydraulic alarms (the daemon applies the
    same rule)."""
    from monitor.detection.offline import detect
    from monitor.model.machinecard import reference_reason

    rec = read_loop(path, cfg, loop)
    reference = reference_reason(model.card, machine_id)
    det = detect(
        model, rec, cfg.alarm, horizon or cfg.horizon, gating=cfg.gating, reference=reference
    )
    return Judged(rec, det, reference)
