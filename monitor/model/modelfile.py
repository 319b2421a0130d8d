"""The model file: everything the detector needs, versioned, self-describing, checksummed.

Format: a numpy ``.npz`` holding the GRNN's arrays plus ``header``, a UTF-8 JSON document
(format name, version, signals, lags, normalisation, sigma, J0, eps0, window, isolation,
training provenance, and since the operating envelope exists ``validity``: the trained
range and occupancy of every signal, see ``monitor.model.envelope``) and ``checksum``, a SHA-256
over the header and every array.  Floats
go through JSON's shortest round-trip repr and arrays are stored raw, so a model loads
back bit-identically.
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from monitor.errors import ModelFileError
from monitor.model.bias import BiasModel
from monitor.model.dgrnn import DGRNN
from monitor.model.envelope import Envelope, envelope_from_patterns
from monitor.model.filecheck import check_header, read_members
from monitor.model.grnn import GRNN
from monitor.model.hold import HoldModel
from monitor.model.lever import LeverModel
from monitor.model.machinecard import ModelCard
from monitor.model.spec import DGRNNSpec, Normalizer
from monitor.model.statistic import registry
from monitor.model.threshold import ThresholdRule
from monitor.signals import DERIVED, SIGNAL_NAMES, contract_name

log = logging.getLogger("monitor")

MODEL_FORMAT = "hydraulic-monitor-dgrnn"
# 2: patterns carry member counts (Specht's clustered GRNN).  The optional header key
# ``validity`` (the training envelope) was added without a version bump: readers that do
# not know it ignore it, and files without it get an envelope derived from their patterns.
# Likewise each statistic's section beside J (``bias``, ``lever``, ``hold``, any member of
# ``monitor.model.statistic``'s registry): a file without it has no such statistic; and
# ``machine`` (the loop and machine trained on): without it, unknown.
MODEL_VERSION = 2
_ARRAYS = ("patterns", "targets", "counts", "pattern_index", "isolation_centroids")


@dataclass(frozen=True)
class Isolation:
    """The fault signatures the isolation compares an alarm's residuals with: a label and
    a unit-length centroid (mean residual per spool regime and output) per fault and
    severity, and the cosine similarity below which the fault is ``unknown``."""

    labels: tuple[str, ...] = ()
    centroids: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    min_similarity: float = 0.5


@dataclass
class MonitorModel:
    """A trained detector: DGRNN, normalisation, window N, threshold and fault isolation."""

    dgrnn: DGRNN
    normalizer: Normalizer
    window_n: int
    threshold: ThresholdRule
    j0: float
    eps0: float
    #: Fault isolation: one signature per label (none: faults are not named).
    isolation: Isolation = field(default_factory=lambda: Isolation())
    #: Per-output bound on |e| (z-units) before J; None keeps eq. 9 literal.  See training.
    residual_clip: tuple[float, ...] | None = None
    training: dict[str, Any] = field(default_factory=dict)
    #: Trained range and occupancy per signal (None: not known; see ``monitor.model.envelope``).
    envelope: Envelope | None = None
    #: The bias statistic B beside J (None: J alone, as the paper; see ``monitor.model.bias``).
    bias: BiasModel | None = None
    #: The full-lever statistic L (None: none; see ``monitor.model.lever``).
    lever: LeverModel | None = None
    #: The hold statistic H (None: none; see ``monitor.model.hold``).
    hold: HoldModel | None = None
    #: The loop and machine trained on (None: not recorded; see ``monitor.model.machinecard``).
    card: ModelCard | None = None
    #: Any other statistic of the family by its key (``monitor.model.statistic``): what its
    #: member keeps in the model file.
    statistics: dict[str, Any] = field(default_factory=dict)

    @property
    def spec(self) -> DGRNNSpec:
        return self.dgrnn.spec

    def header(self) -> dict[str, Any]:
        g = self.dgrnn.grnn
        head = {
            "format": MODEL_FORMAT,
            "version": MODEL_VERSION,
            "spec": self.spec.to_dict(),
            "normalizer": self.normalizer.to_dict(),
            "sigma": float(g.sigma_),
            "sigma_rule": g.sigma_rule_,
            "loo_error": float(g.loo_error_),
            "exclude_neighbours": int(g.exclude_neighbours_),
            "thinning": g.thinning_,
            "residual_clip": None if self.residual_clip is None else list(self.residual_clip),
            "threshold": self.threshold.to_dict(),
            "isolation": {
                "labels": list(self.isolation.labels),
                "min_similarity": float(self.isolation.min_similarity),
            },
            "training": self.training,
        }
        if self.envelope is not None:
            head["validity"] = self.envelope.to_dict()
        for stat in registry():  # J's window and thresholds, each other member's section
            params = stat.get(self)
            if params is not None:
                stat.write(head, params)
        if self.card is not None:
            head["machine"] = self.card.to_dict()
        return head


def _checksum(header_bytes: bytes, arrays: dict[str, np.ndarray]) -> str:
    h = hashlib.sha256(header_bytes)
    for name in _ARRAYS:
        a = np.ascontiguousarray(arrays[name])
        h.update(name.encode() + str(a.dtype).encode() + str(a.shape).encode() + a.tobytes())
    return h.hexdigest()


def save_model(path: str | Path, model: MonitorModel) -> None:
    g = model.dgrnn.grnn
    arrays = {
        "patterns": np.asarray(g.patterns_, dtype=np.float64),
        "targets": np.asarray(g.targets_, dtype=np.float64),
        "counts": np.asarray(g.counts_, dtype=np.float64),
        "pattern_index": np.asarray(g.pattern_index_, dtype=np.int64),
        "isolation_centroids": np.asarray(model.isolation.centroids, dtype=np.float64),
    }
    header = json.dumps(model.header()).encode("utf-8")
    checksum = _checksum(header, arrays).encode("ascii")
    path = Path(path)
    with path.open("wb") as fh:
        np.savez(
            fh,
            header=np.frombuffer(header, dtype=np.uint8),
            checksum=np.frombuffer(checksum, dtype=np.uint8),
            # The arrays' names are keywords; mypy also matches them to savez's own
            # allow_pickle flag (numpy >= 2.1), which no name here is.
            **arrays,  # type: ignore[arg-type]
        )


def _brief(exc: BaseException) -> str:
    """An exception's text for a one-line message: whitespace folded, cut to 120 characters
    (a check may quote a whole header section)."""
    text = " ".join(str(exc).split())
    return text if len(text) <= 120 else text[:117] + "..."


def load_model(path: str | Path) -> MonitorModel:
    """Load and verify a model file; any problem is a ``ModelFileError`` naming the file."""
    path = Path(path)
    try:
        data = read_members(path)
    except FileNotFoundError:
        raise ModelFileError(f"{path}: no such model file") from None
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise ModelFileError(f"{path}: not a monitor model file ({_brief(exc)})") from None
    missing = [k for k in ("header", "checksum", *_ARRAYS) if k not in data]
    if missing:
        raise ModelFileError(f"{path}: not a monitor model file (missing {', '.join(missing)})")
    header_bytes = data["header"].tobytes()
    try:
        header = json.loads(header_bytes.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError):
        raise ModelFileError(f"{path}: corrupt model header") from None
    if not isinstance(header, dict):
        raise ModelFileError(f"{path}: corrupt model header (not a JSON object)")
    if header.get("format") != MODEL_FORMAT:
        fmt = str(header.get("format"))[:40]
        raise ModelFileError(f"{path}: not a monitor model file (format {fmt!r})")
    if header.get("version") != MODEL_VERSION:
        raise ModelFileError(
            f"{path}: model file version {header.get('version')!r}; this monitor reads version "
            f"{MODEL_VERSION} (retrain with `monitor train`)"
        )
    if _checksum(header_bytes, data) != data["checksum"].tobytes().decode("ascii", "replace"):
        raise ModelFileError(f"{path}: checksum mismatch, the model file is corrupt")
    try:
        check_header(header)
        model = _from_header(header, data)
        derived = model.envelope is None
        if derived:  # in the try: it relies on the normalizer's names matching the spec
            model.envelope = envelope_from_patterns(model)
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise ModelFileError(f"{path}: inconsistent model file ({_brief(exc)})") from None
    if derived and model.envelope is not None:
        log.info(
            "%s: no stored training envelope (a model file from before it existed); validity "
            "ranges derived from its patterns: %s",
            path,
            ", ".join(
                f"{s} {a:.4g}..{b:.4g}"
                for s, a, b in zip(
                    model.envelope.signals, model.envelope.lo, model.envelope.hi, strict=True
                )
            ),
        )
    return model


def _from_header(header: dict[str, Any], data: dict[str, np.ndarray]) -> MonitorModel:
    spec = DGRNNSpec.from_dict(header["spec"])
    # Another loop's signal is named SIGNAL@LOOP (``monitor.signals.neighbour``).
    unknown = [
        v for v in spec.variables if contract_name(v) not in SIGNAL_NAMES and v not in DERIVED
    ]
    if unknown:
        raise ValueError(f"the model uses signals this monitor does not know: {unknown}")
    normalizer = Normalizer.from_dict(header["normalizer"])
    unscaled = [v for v in spec.variables if v not in list(normalizer.names_)]
    if unscaled:
        raise ValueError(f"the normalizer has no mean and std for {', '.join(unscaled)[:80]}")
    grnn = GRNN.from_arrays(
        data["patterns"],
        data["targets"],
        header["sigma"],
        counts_=data["counts"],
        sigma_rule_=header["sigma_rule"],
        loo_error_=header["loo_error"],
        exclude_neighbours_=header["exclude_neighbours"],
        thinning_=header["thinning"],
        pattern_index_=data["pattern_index"],
    )
    dgrnn = DGRNN(spec, grnn)
    dgrnn._fitted()  # shape check against the spec
    iso = header["isolation"]
    centroids = data["isolation_centroids"]
    if len(iso["labels"]) != centroids.shape[0]:
        raise ValueError("isolation labels and centroids disagree")
    model = MonitorModel(
        dgrnn=dgrnn,
        normalizer=normalizer,
        window_n=0,
        threshold=ThresholdRule(**header["threshold"]),
        j0=math.nan,
        eps0=math.nan,
        isolation=Isolation(tuple(iso["labels"]), centroids, float(iso["min_similarity"])),
        residual_clip=None if header["residual_clip"] is None else tuple(header["residual_clip"]),
        training=header["training"],
        envelope=Envelope.from_dict(header["validity"]) if "validity" in header else None,
        card=ModelCard.from_dict(header["machine"]) if "machine" in header else None,
    )
    for stat in registry():  # J's window and thresholds, each other member's section
        stat.put(model, stat.read(header, len(spec.outputs)))
    return model
