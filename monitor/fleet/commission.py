"""Commissioning in `monitor fleet run`: each machine's model, trained on the cluster from
its commissioning logs, reused while they (and the training settings) are unchanged, or the
default model for a machine without them or whose training failed."""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

from monitor.fleet import pipeline
from monitor.fleet.cluster import RunOptions, Stop, wait
from monitor.fleet.layout import Fleet, Machine
from monitor.fleet.progress import Progress
from monitor.fleet.store import ResultStore
from monitor.io.digest import sha256_file


def train_task(
    paths: list[str], config: str | None, isolation: str, reference: bytes, machine_id: str
) -> bytes:
    return pipeline.train_model_bytes(paths, config, isolation, reference, machine_id)


def _settings(default: bytes, opts: RunOptions) -> dict[str, Any]:
    """What every machine's model is trained with besides its own commissioning files (hashed
    once per run: the default model is megabytes)."""
    config = None if opts.config is None else sha256_file(Path(opts.config))
    return {
        "reference_sha256": hashlib.sha256(default).hexdigest(),
        "isolation": opts.isolation,
        "config_sha256": config,
        "train": pipeline.COMMISSIONING,
    }


def _manifest(m: Machine, fleet: Fleet, settings: dict[str, Any]) -> dict[str, Any]:
    """What a machine's model is trained from: a stored model trained from the same is
    reused, so a daily rerun commissions only new or changed machines."""
    return {
        "commissioning": {fleet.relative(p): sha256_file(p) for p in m.commissioning},
        **settings,
    }


#: machine id -> (a future or the bytes of its model, the model's label)
Models = dict[str, tuple[Any, str]]


def models(
    client: Any,
    fleet: Fleet,
    store: ResultStore,
    opts: RunOptions,
    needed: set[str],
    stop: Stop,
    progress: Progress,
) -> Models:
    """machine id -> (future or bytes of its model, model label), for the ``needed`` ones."""
    default = pipeline.default_model_bytes(opts.default_model, opts.config)
    out, manifests, to_train = _known(fleet, store, needed, default, opts, progress)
    _submit(client, to_train, opts, default, out, stop, progress)
    reused = [mid for mid, (_, label) in out.items() if label == "commissioned"]
    if reused:
        progress.say(f"fleet: {len(reused)} machine model(s) reused (commissioning unchanged)")
    _collect(out, manifests, default, store, stop, progress)
    for mid, (data, label) in out.items():
        if label.startswith("default"):
            store.save_model(mid, data, None)
    return out


def _known(
    fleet: Fleet,
    store: ResultStore,
    needed: set[str],
    default: bytes,
    opts: RunOptions,
    progress: Progress,
) -> tuple[Models, dict[str, dict[str, Any]], list[Machine]]:
    """The models known without training (the default one, a stored one trained from the
    same), each machine's manifest, and the machines to train."""
    out: Models = {}
    manifests: dict[str, dict[str, Any]] = {}
    settings = _settings(default, opts)
    to_train: list[Machine] = []
    for m in fleet.machines:
        if m.machine_id not in needed:
            continue
        if not m.commissioning:
            progress.say(
                f"fleet: {m.machine_id}: no commissioning data, judged with the default model"
            )
            out[m.machine_id] = (default, "default")
            continue
        manifests[m.machine_id] = manifest = _manifest(m, fleet, settings)
        cached = store.cached_model(m.machine_id, manifest)
        if cached is not None:
            out[m.machine_id] = (cached, "commissioned")
        else:
            to_train.append(m)
    return out, manifests, to_train


def _submit(
    client: Any,
    to_train: list[Machine],
    opts: RunOptions,
    default: bytes,
    out: Models,
    stop: Stop,
    progress: Progress,
) -> None:
    """One training task per machine, into ``out`` as ``training``."""
    if to_train:
        progress.commissioning(len(to_train))
    for i, m in enumerate(to_train):
        # The default model floors the commissioned thresholds (minutes cannot show the
        # tail of hours: monitor.training.train.floor_thresholds).
        fut = client.submit(
            train_task,
            [str(p) for p in m.commissioning],
            opts.config,
            opts.isolation,
            default,
            m.machine_id,
            key=f"train-{m.machine_id}",
            pure=False,
        )
        if i == 0:  # alone: it fills numba's cache for the training kernels
            wait([fut], stop, progress)  # a failure is reported below, with the others'
        out[m.machine_id] = (fut, "training")


def _collect(
    out: Models,
    manifests: dict[str, dict[str, Any]],
    default: bytes,
    store: ResultStore,
    stop: Stop,
    progress: Progress,
) -> None:
    """Wait for each training: its model stored, or the default one for a failed one."""
    for mid, (fut, label) in list(out.items()):
        if label != "training":
            continue
        wait([fut], stop, progress)
        try:
            data = fut.result()
        except Exception as exc:  # noqa: BLE001 - any failure of a machine's training
            progress.say(
                f"fleet: {mid}: commissioning failed ({exc}); judged with the default model"
            )
            out[mid] = (default, f"default (commissioning failed: {exc})")
            continue
        # Whether each statistic earned its threshold, and why not (the support rule's
        # line), beside what the model was trained from.
        store.save_model(mid, data, manifests[mid], pipeline.statistic_notes(data))
        out[mid] = (fut, "commissioned")
        progress.commissioned()
