"""Commissioning in `monitor fleet run`: each machine's model (a whole machine's: one per
loop of the config's ``loops:``, and its pump's margin law with the config's ``pump:``),
trained on the cluster from its commissioning logs, reused while they (and the training
settings) are unchanged, or the default model (the loop's model of the config) for a machine
without them or whose training failed (a pump has none: it is then not judged)."""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

from monitor.fleet import pipeline
from monitor.fleet.cluster import RunOptions, Stop, wait
from monitor.fleet.layout import Fleet, Machine
from monitor.fleet.progress import Progress
from monitor.fleet.pumpjob import PUMP, pump_notes, train_pump_task
from monitor.fleet.store import ResultStore
from monitor.io.digest import sha256_file


def train_task(
    paths: list[str],
    config: str | None,
    isolation: str,
    reference: bytes,
    machine_id: str,
    loop: str | None = None,
) -> bytes:
    return pipeline.train_model_bytes(paths, config, isolation, reference, machine_id, loop)


#: A model's key: (machine id, loop; None for a log judged as one loop).
Unit = tuple[str, str | None]


def model_name(unit: Unit) -> str:
    """The model's name in RESULTS/models: ``M01`` (one loop) or ``M01.stick``."""
    machine, loop = unit
    return machine if loop is None else f"{machine}.{loop}"


def _settings(default: bytes, opts: RunOptions, loop: str | None) -> dict[str, Any]:
    """What every machine's model (of ``loop``) is trained with besides its own
    commissioning files (hashed once per run: the default model is megabytes)."""
    config = None if opts.config is None else sha256_file(Path(opts.config))
    out = {
        "reference_sha256": hashlib.sha256(default).hexdigest(),
        "isolation": opts.isolation,
        "config_sha256": config,
        "train": pipeline.COMMISSIONING,
    }
    return out if loop is None else {**out, "loop": loop}


def _manifest(m: Machine, fleet: Fleet, settings: dict[str, Any]) -> dict[str, Any]:
    """What a machine's model is trained from: a stored model trained from the same is
    reused, so a daily rerun commissions only new or changed machines."""
    return {
        "commissioning": {fleet.relative(p): sha256_file(p) for p in m.commissioning},
        **settings,
    }


#: (machine id, loop) -> (a future or the bytes of its model, the model's label)
Models = dict[Unit, tuple[Any, str]]


def models(
    client: Any,
    fleet: Fleet,
    store: ResultStore,
    opts: RunOptions,
    needed: set[Unit],
    stop: Stop,
    progress: Progress,
) -> Models:
    """(machine id, loop) -> (future or bytes of its model, model label), for the
    ``needed`` ones."""
    loops = sorted({loop for _, loop in needed}, key=lambda x: (x is not None, x or ""))
    # The pump has no default model: its law is each machine's own (uncommissioned: unjudged).
    defaults = {
        loop: b""
        if loop == PUMP
        else pipeline.default_model_bytes(opts.default_model, opts.config, loop)
        for loop in loops
    }
    out, manifests, to_train = _known(fleet, store, needed, defaults, opts, progress)
    _submit(client, to_train, opts, defaults, out, stop, progress)
    reused = [u for u, (_, label) in out.items() if label == "commissioned"]
    if reused:
        what = "machine" if loops == [None] else "loop"
        progress.say(f"fleet: {len(reused)} {what} model(s) reused (commissioning unchanged)")
    _collect(out, manifests, defaults, store, stop, progress)
    for unit, (data, label) in out.items():
        if label.startswith("default") and data:
            store.save_model(model_name(unit), data, None)
    return out


def _known(
    fleet: Fleet,
    store: ResultStore,
    needed: set[Unit],
    defaults: dict[str | None, bytes],
    opts: RunOptions,
    progress: Progress,
) -> tuple[Models, dict[Unit, dict[str, Any]], list[tuple[Machine, str | None]]]:
    """The models known without training (the default one, a stored one trained from the
    same), each model's manifest, and the (machine, loop)s to train."""
    out: Models = {}
    manifests: dict[Unit, dict[str, Any]] = {}
    settings = {loop: _settings(d, opts, loop) for loop, d in defaults.items()}
    to_train: list[tuple[Machine, str | None]] = []
    for m in fleet.machines:
        loops = [loop for mid, loop in needed if mid == m.machine_id]
        if loops and not m.commissioning:
            progress.say(
                f"fleet: {m.machine_id}: no commissioning data, judged with the default model"
                + ("" if loops == [None] else "s: its loops uncommissioned")
            )
        for loop in sorted(loops, key=lambda x: x or ""):
            unit = (m.machine_id, loop)
            if not m.commissioning:
                out[unit] = (defaults[loop], "default")
                continue
            manifests[unit] = manifest = _manifest(m, fleet, settings[loop])
            cached = store.cached_model(model_name(unit), manifest)
            if cached is not None:
                out[unit] = (cached, "commissioned")
            else:
                to_train.append((m, loop))
    return out, manifests, to_train


def _submit(
    client: Any,
    to_train: list[tuple[Machine, str | None]],
    opts: RunOptions,
    defaults: dict[str | None, bytes],
    out: Models,
    stop: Stop,
    progress: Progress,
) -> None:
    """One training task per machine (and loop), into ``out`` as ``training``."""
    if to_train:
        progress.commissioning(len(to_train))
    for i, (m, loop) in enumerate(to_train):
        # The default model floors the commissioned thresholds (minutes cannot show the
        # tail of hours: monitor.training.train.floor_thresholds).
        unit = (m.machine_id, loop)
        paths = [str(p) for p in m.commissioning]
        if loop == PUMP:
            fut = client.submit(
                train_pump_task,
                paths,
                opts.config,
                m.machine_id,
                key=f"train-{model_name(unit)}",
                pure=False,
            )
        else:
            fut = client.submit(
                train_task,
                paths,
                opts.config,
                opts.isolation,
                defaults[loop],
                m.machine_id,
                loop,
                key=f"train-{model_name(unit)}",
                pure=False,
            )
        if i == 0:  # alone: it fills numba's cache for the training kernels
            wait([fut], stop, progress)  # a failure is reported below, with the others'
        out[unit] = (fut, "training")


def _collect(
    out: Models,
    manifests: dict[Unit, dict[str, Any]],
    defaults: dict[str | None, bytes],
    store: ResultStore,
    stop: Stop,
    progress: Progress,
) -> None:
    """Wait for each training: its model stored, or the default one for a failed one."""
    for unit, (fut, label) in list(out.items()):
        if label != "training":
            continue
        wait([fut], stop, progress)
        name = model_name(unit)
        try:
            data = fut.result()
        except Exception as exc:  # noqa: BLE001 - any failure of a machine's training
            progress.say(
                f"fleet: {name}: commissioning failed ({exc}); judged with the default model"
            )
            out[unit] = (defaults[unit[1]], f"default (commissioning failed: {exc})")
            continue
        # Whether each statistic earned its threshold, and why not (the support rule's
        # line), beside what the model was trained from.
        notes = pump_notes(data) if unit[1] == PUMP else pipeline.statistic_notes(data)
        store.save_model(name, data, manifests[unit], notes)
        out[unit] = (fut, "commissioned")
        progress.commissioned()
