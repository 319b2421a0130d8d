"""The shared pump's margin law: what ``monitor train --pump`` learns and the pump rule
(``monitor.detection.pump``) judges with, in a small JSON model file.

A load-sensing pump's regulator holds PP = PLS + margin - band x displacement, and the
displacement is (the sections' total flow + the pump's own leakage) / full flow.  So the
margin's deficit, PLS + margin - PP with PLS the highest port an open section feeds, is
linear in the sections' total flow and (through the leakage) in PP:

    deficit_bar = flow_coef x sum(QP) + pp_coef x PP + offset_bar

A worn pump leaks more; its regulator makes the leak up with displacement, so no section
sees less flow, but the deficit grows by band x extra leakage / full flow: the mean
residual of the law over a window of steady samples rises.  The file holds the law fitted
on the machine's own normal operation, the window, and the threshold its held-out data
supports (or why there is none: the rule is then off).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from monitor.errors import ModelFileError

KIND = "pump_margin_law"
VERSION = 1


@dataclass(frozen=True)
class MarginLaw:
    """deficit_bar = flow_coef x total flow (L/min) + pp_coef x PP (bar) + offset_bar."""

    flow_coef: float  # bar per L/min (band / full flow)
    pp_coef: float  # bar per bar (band x the healthy leakage coefficient / full flow)
    offset_bar: float

    def deficit(self, flow_lpm: float, pp_bar: float) -> float:
        return self.flow_coef * flow_lpm + self.pp_coef * pp_bar + self.offset_bar


@dataclass(frozen=True)
class Counting:
    """Which samples count and how they are pooled.  A sample counts when a section's spool
    is open beyond ``open_pct``, every spool command has been steady (no step over
    ``step_pct``) for ``steady_n`` samples and the sections draw over ``min_flow_lpm``.
    The statistic is the mean residual of the last ``blocks`` x ``block_n`` counted
    samples, new at the end of each block."""

    margin_bar: float  # the config's plausibility.ls_margin_bar when trained
    open_pct: float = 5.0
    step_pct: float = 0.5
    steady_n: int = 50  # 0.5 s at 100 Hz
    min_flow_lpm: float = 2.0
    block_n: int = 200  # 2 s of counted samples
    blocks: int = 10  # a 20 s window of counted samples

    @property
    def window_n(self) -> int:
        return self.block_n * self.blocks


@dataclass(frozen=True)
class PumpModel:
    """The law, the counting, the threshold (bar of mean residual; None: the rule is off,
    ``off_reason`` says why) and what the threshold rests on (``support``)."""

    law: MarginLaw
    counting: Counting
    threshold_bar: float | None
    off_reason: str | None = None
    support: dict[str, Any] = field(default_factory=dict)
    trained: dict[str, Any] = field(default_factory=dict)

    @property
    def on(self) -> bool:
        return self.threshold_bar is not None

    def to_dict(self) -> dict[str, Any]:
        return {"kind": KIND, "version": VERSION, **asdict(self)}


def save_pump_model(model: PumpModel, path: str | Path) -> None:
    Path(path).write_text(json.dumps(model.to_dict(), indent=2) + "\n", encoding="utf-8")


def load_pump_model(path: str | Path) -> PumpModel:
    """A pump model file; anything else (another kind, version, a missing or non-finite
    number) is one ``ModelFileError`` naming the file and the key."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, ValueError) as exc:
        raise ModelFileError(f"{path}: not a pump model file ({exc})") from None
    return pump_model_from_text(text, path)


def pump_model_from_text(text: str, path: str | Path) -> PumpModel:
    """The pump model of a pump model file's text (``path`` names it in a message); checked
    as :func:`load_pump_model` checks a file (the fleet ships models as bytes)."""
    try:
        data = json.loads(text)
    except ValueError as exc:
        raise ModelFileError(f"{path}: not a pump model file ({exc})") from None
    if not isinstance(data, dict) or data.get("kind") != KIND:
        raise ModelFileError(f"{path}: not a pump model file (kind {KIND!r} expected)")
    if data.get("version") != VERSION:
        raise ModelFileError(
            f"{path}: pump model version {data.get('version')!r}, this monitor reads {VERSION}"
        )
    try:
        law = MarginLaw(**{k: _finite(data["law"][k], f"law.{k}", path) for k in _LAW_KEYS})
        counting = Counting(**data["counting"])
        threshold = data["threshold_bar"]
    except (KeyError, TypeError) as exc:
        raise ModelFileError(f"{path}: pump model lacks or mistypes {exc}") from None
    if threshold is not None:
        threshold = _finite(threshold, "threshold_bar", path)
        if threshold <= 0:
            raise ModelFileError(f"{path}: threshold_bar must be > 0, got {threshold}")
    if counting.block_n < 1 or counting.blocks < 1 or counting.steady_n < 0:
        raise ModelFileError(f"{path}: counting.block_n, blocks must be >= 1, steady_n >= 0")
    return PumpModel(
        law,
        counting,
        threshold,
        data.get("off_reason"),
        dict(data.get("support") or {}),
        dict(data.get("trained") or {}),
    )


_LAW_KEYS = ("flow_coef", "pp_coef", "offset_bar")


def _finite(value: Any, key: str, path: str | Path) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ModelFileError(f"{path}: {key} must be a finite number, got {value!r}")
    return float(value)
